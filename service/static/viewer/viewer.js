// The PBD-AG viewer: a top-down map of one scene at any seq, its events, one track's belief and
// explanation, and the verification queue. Plain DOM and canvas over the v1 API, same origin.

const EVENT_PAGE = 40;
const HEAD_POLL_MS = 3000;
const OBJECT_RADIUS_PX = 6;
const OCCUPANCY_RGBA = {
  0: [206, 212, 218, 255], // unknown
  1: [255, 255, 255, 255], // free
  2: [52, 58, 64, 255], // occupied
};

const $ = (id) => document.getElementById(id);

const view = {
  sceneId: null,
  head: 0,
  seq: 0,
  graph: null,
  occupancy: null,
  selected: null,
  eventsAfter: -1, // the events list shows seq in (eventsAfter, eventsAfter + EVENT_PAGE]
  shapes: [], // what the map drew, for clicks: {id, kind, x, y, w, h} in canvas pixels
  renderTicket: 0,
};

// --- the API -------------------------------------------------------------------------------

function token() {
  return sessionStorage.getItem("pbdag-token") || "";
}

class ApiError extends Error {
  constructor(status, problem) {
    super(problem && problem.detail ? `${status}: ${problem.detail}` : `HTTP ${status}`);
    this.status = status;
  }
}

async function api(path, { method = "GET", body } = {}) {
  const headers = { Accept: "application/json" };
  if (token()) headers.Authorization = `Bearer ${token()}`;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const response = await fetch(path, {
    method,
    headers,
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  const payload = await response.json().catch(() => null);
  if (!response.ok) throw new ApiError(response.status, payload);
  return payload;
}

const scenePath = (suffix = "") => `/v1/scenes/${encodeURIComponent(view.sceneId)}${suffix}`;

function say(text, ok = false) {
  $("status").textContent = text;
  $("status").className = ok ? "ok" : "";
}

function failed(error) {
  const needsToken = error instanceof ApiError && error.status === 401;
  $("token").classList.toggle("needed", needsToken);
  if (!needsToken) {
    say(String(error.message || error));
    return;
  }
  say(token()
    ? "This service needs a token: the one given was refused; paste another above and press Use."
    : "This service needs a token: paste a read token above and press Use "
      + "(make one with: pbdag token create --name viewer --scope read).");
  $("token").focus();
}

// --- DOM helpers ---------------------------------------------------------------------------

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs)) {
    if (name === "onclick") {
      node.addEventListener("click", value);
      if (tag === "li" || tag === "strong") {
        node.tabIndex = 0; // clickable lines are reachable with the keyboard too
        node.addEventListener("keydown", (event) => event.key === "Enter" && value(event));
      }
    }
    else if (name === "className") node.className = value;
    else if (name === "dataset") Object.assign(node.dataset, value);
    else node.setAttribute(name, value);
  }
  for (const child of children) {
    if (child !== null && child !== undefined) {
      node.append(child instanceof Node ? child : String(child));
    }
  }
  return node;
}

const fixed = (value, digits = 2) => (value === null || value === undefined ? "-" : Number(value).toFixed(digits));
const vector = (values) => (values ? `[${values.map((v) => fixed(v)).join(", ")}]` : "-");
const topClasses = (probabilities, n = 3) =>
  Object.entries(probabilities || {})
    .sort((a, b) => b[1] - a[1])
    .slice(0, n)
    .map(([label, p]) => `${label} ${fixed(p)}`)
    .join(", ");

// --- scenes and the head -------------------------------------------------------------------

async function loadScenes() {
  const scenes = [];
  for (let after = null; ; ) {
    const page = await api(`/v1/scenes?limit=1000${after ? `&after=${encodeURIComponent(after)}` : ""}`);
    scenes.push(...page.scenes);
    if (!page.next_after) break;
    after = page.next_after;
  }
  const select = $("scene-select");
  select.replaceChildren(
    ...scenes.map((scene) => el("option", { value: scene.id }, `${scene.name} (${scene.id})`)),
  );
  const wanted = new URLSearchParams(location.search).get("scene");
  const chosen = scenes.find((s) => s.id === wanted) || scenes[scenes.length - 1];
  if (!chosen) {
    say("No scene yet: post one with POST /v1/scenes.");
    return;
  }
  select.value = chosen.id;
  await openScene(chosen.id);
}

async function openScene(sceneId) {
  view.sceneId = sceneId;
  view.selected = null;
  const url = new URL(location.href);
  url.searchParams.set("scene", sceneId);
  history.replaceState(null, "", url);
  $("track-detail").replaceChildren(el("p", { className: "hint" }, "Click a track on the map or in the list."));
  const scene = await api(scenePath());
  setHead(scene.head_seq, true);
  startFeed();
  await Promise.all([showSeq(view.head), loadVerifications()]);
}

function setHead(head, moveSlider) {
  view.head = head;
  const slider = $("seq");
  slider.max = String(head);
  if (moveSlider) slider.value = String(head);
}

async function pollHead() {
  if (!view.sceneId || feed.controller) return;  // the feed brings the head while following
  try {
    const scene = await api(scenePath());
    if (scene.head_seq === view.head) return;
    // Scrubbing back unchecks "follow the head" (the slider's handler); checked, the view
    // moves to every new head.
    const follow = $("follow").checked;
    setHead(scene.head_seq, follow);
    if (follow) await showSeq(view.head);
    await loadVerifications();
  } catch (error) {
    failed(error);
  }
}

// --- following the head: the live feed -------------------------------------------------------
// While "follow the head" is checked the page reads GET .../events/stream, with fetch and a
// stream reader (EventSource cannot send the bearer token), and redraws the newest seq at most
// every FEED_DEBOUNCE_MS while events arrive. A lost or dropped stream is resumed with
// Last-Event-ID after a backoff; unchecked, the page polls the head for the slider's range.

const FEED_DEBOUNCE_MS = 150;
const FEED_RETRY_MS = [500, 10000]; // first and longest wait before resuming a lost stream
const feed = { controller: null, lastId: -1, timer: null, retry: null, retryMs: 500, events: 0, refreshes: 0 };

function stopFeed() {
  if (feed.controller) feed.controller.abort();
  feed.controller = null;
  clearTimeout(feed.timer);
  clearTimeout(feed.retry);
}

// Follows the open scene from seq `after` on (default: the head the page knows).
function startFeed(after = view.head) {
  stopFeed();
  if (!view.sceneId || !$("follow").checked) return;
  const controller = new AbortController();
  const sceneId = view.sceneId;
  feed.controller = controller;
  feed.lastId = after;
  readFeed(sceneId, controller)
    .then((ended) => ended && say(`scene ${sceneId}: the feed ended (${ended})`))
    .catch((error) => controller.signal.aborted || failed(error))
    .finally(() => {
      if (feed.controller !== controller) return; // stopped, or another scene's feed
      feed.controller = null;
      if (controller.signal.aborted) return;
      feed.retry = setTimeout(resumeFeed, feed.retryMs);
      feed.retryMs = Math.min(feed.retryMs * 2, FEED_RETRY_MS[1]);
    });
}

function resumeFeed() {
  if (!feed.controller) startFeed(Math.max(feed.lastId, view.head));
}

// Reads one stream until it closes; the reason of an `end` message (no resuming then), else null.
async function readFeed(sceneId, controller) {
  const headers = { Accept: "text/event-stream", "Last-Event-ID": String(feed.lastId) };
  if (token()) headers.Authorization = `Bearer ${token()}`;
  const response = await fetch(`/v1/scenes/${encodeURIComponent(sceneId)}/events/stream`, {
    headers,
    cache: "no-store",
    signal: controller.signal,
  });
  if (!response.ok) throw new ApiError(response.status, await response.json().catch(() => null));
  const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
  let ended = null;
  const parse = sseParser((message) => {
    if (message.event === "end") ended = JSON.parse(message.data).reason || "end";
    else if (message.event !== "dropped") feedEvent(Number(message.id));
  });
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return null;
    parse(value);
    if (ended) {
      controller.abort();
      return ended;
    }
  }
}

// An incremental text/event-stream parser (lines end in CRLF, LF or CR, even across chunks;
// `:` comments; data lines joined with newlines; a blank line dispatches).
function sseParser(dispatch) {
  let buffer = "";
  let afterCr = false;
  let message = { event: "", data: [], id: null };
  return (text) => {
    if (afterCr && text.startsWith("\n")) text = text.slice(1);
    afterCr = text.endsWith("\r");
    const lines = (buffer + text).split(/\r\n|\r|\n/);
    buffer = lines.pop();
    for (const line of lines) {
      if (line === "") {
        if (message.data.length) {
          dispatch({ event: message.event || "message", data: message.data.join("\n"), id: message.id });
        }
        message = { event: "", data: [], id: message.id };
        continue;
      }
      if (line.startsWith(":")) continue;
      const colon = line.indexOf(":");
      const name = colon < 0 ? line : line.slice(0, colon);
      let value = colon < 0 ? "" : line.slice(colon + 1);
      if (value.startsWith(" ")) value = value.slice(1);
      if (name === "event") message.event = value;
      else if (name === "data") message.data.push(value);
      else if (name === "id" && !value.includes("\0")) message.id = value;
    }
  };
}

function feedEvent(seq) {
  if (!(seq > feed.lastId)) return; // seen already
  feed.lastId = seq;
  feed.retryMs = FEED_RETRY_MS[0];
  feed.events += 1;
  document.body.dataset.feedEvents = String(feed.events);
  clearTimeout(feed.timer);
  feed.timer = setTimeout(() => refreshFromFeed().catch(failed), FEED_DEBOUNCE_MS);
}

async function refreshFromFeed() {
  const follow = $("follow").checked;
  setHead(Math.max(view.head, feed.lastId), follow);
  feed.refreshes += 1;
  document.body.dataset.feedRefreshes = String(feed.refreshes);
  if (follow) await showSeq(view.head);
  await loadVerifications();
}

// --- one seq: graph, occupancy, events ------------------------------------------------------

async function showSeq(seq) {
  if (!view.sceneId) return;  // no scene open (no token yet): nothing to ask for
  const ticket = ++view.renderTicket;
  view.seq = seq;
  $("seq-label").textContent = String(seq);
  const include = $("show-all").checked ? "all" : "published";
  try {
    const [graph, occupancy] = await Promise.all([
      api(scenePath(`/graph?as_of=${seq}&include=${include}`)),
      api(scenePath(`/occupancy?as_of=${seq}&format=json`)).catch(() => null),
    ]);
    if (ticket !== view.renderTicket) return; // the slider moved on meanwhile
    view.graph = graph;
    view.occupancy = occupancy;
    drawMap();
    listTracks();
    view.eventsAfter = Math.max(-1, seq - EVENT_PAGE);
    await loadEvents(ticket);
    if (view.selected) await showTrack(view.selected, ticket);
    if (ticket !== view.renderTicket) return;
    document.body.dataset.seq = String(seq); // the page shows this seq completely
    say(`scene ${view.sceneId} at seq ${seq} of ${view.head}`, true);
  } catch (error) {
    failed(error);
  }
}

function listTracks() {
  const nodes = [...view.graph.nodes].sort((a, b) =>
    a.kind === b.kind ? a.label.localeCompare(b.label) : a.kind === "fixture" ? -1 : 1);
  $("tracks-seq").textContent = String(view.graph.seq);
  $("tracks").dataset.seq = String(view.graph.seq);
  $("tracks").replaceChildren(
    ...nodes.map((node) =>
      el(
        "li",
        {
          className: node.id === view.selected ? "selected" : "",
          dataset: { track: node.id, label: node.label, state: node.state, kind: node.kind },
          onclick: () => selectTrack(node.id),
        },
        `${node.label} `,
        el("span", { className: "track-id" }, `${node.id} `),  // five desks are five ids
        el("span", { className: `state state-${node.state}` }, `${node.kind} ${node.state} p=${fixed(node.p_exist)}`),
        node.parent ? el("span", { className: "state" }, ` on ${labelOf(node.parent)}`) : null,
      ),
    ),
  );
}

function labelOf(trackId) {
  const node = view.graph && view.graph.nodes.find((n) => n.id === trackId);
  return node ? `${node.label} (${trackId})` : trackId;
}

async function loadEvents(ticket = view.renderTicket) {
  const after = view.eventsAfter;
  const page = await api(scenePath(`/events?after=${after}&limit=${EVENT_PAGE}`));
  if (ticket !== view.renderTicket) return;
  const events = page.events;
  $("events-range").textContent = events.length
    ? `seq ${events[0].seq} to ${events[events.length - 1].seq}` : "no events";
  $("events-earlier").disabled = after < 0;
  $("events-later").disabled = page.next_after === null;
  $("events").replaceChildren(
    ...events.map((event) =>
      el(
        "li",
        {
          className: event.seq === view.seq ? "current" : "",
          dataset: { seq: String(event.seq), type: event.type },
          onclick: () => event.track_id && selectTrack(event.track_id),
        },
        `${event.seq} ${event.type} `,
        el("span", { className: "state" }, [event.track_id, event.state, event.frame_id].filter(Boolean).join(" ")),
      ),
    ),
  );
  const current = $("events").querySelector("li.current");
  if (current) current.scrollIntoView({ block: "nearest" });
}

function pageEvents(direction) {
  view.eventsAfter = Math.max(-1, view.eventsAfter + direction * EVENT_PAGE);
  loadEvents().catch(failed);
}

// --- the map -------------------------------------------------------------------------------

function worldBounds() {
  const xs = [];
  const ys = [];
  const occupancy = view.occupancy;
  if (occupancy && occupancy.shape[0] > 0 && occupancy.shape[1] > 0) {
    const [rows, cols] = occupancy.shape;
    xs.push(occupancy.origin[0], occupancy.origin[0] + cols * occupancy.resolution_m);
    ys.push(occupancy.origin[1], occupancy.origin[1] + rows * occupancy.resolution_m);
  }
  for (const node of view.graph.nodes) {
    xs.push(node.center[0] - node.extent[0] / 2, node.center[0] + node.extent[0] / 2);
    ys.push(node.center[1] - node.extent[1] / 2, node.center[1] + node.extent[1] / 2);
  }
  if (!xs.length) return { minX: -1, maxX: 1, minY: -1, maxY: 1 };
  const margin = 0.3;
  return {
    minX: Math.min(...xs) - margin, maxX: Math.max(...xs) + margin,
    minY: Math.min(...ys) - margin, maxY: Math.max(...ys) + margin,
  };
}

function occupancyImage(occupancy) {
  const [rows, cols] = occupancy.shape;
  const image = new ImageData(cols, rows);
  let cell = 0;
  for (let i = 0; i < occupancy.cells.length; i += 2) {
    const rgba = OCCUPANCY_RGBA[occupancy.cells[i]] || OCCUPANCY_RGBA[0];
    for (let k = 0; k < occupancy.cells[i + 1]; k += 1, cell += 1) {
      const row = Math.floor(cell / cols);
      const col = cell % cols;
      const offset = ((rows - 1 - row) * cols + col) * 4; // row 0 is the southernmost: draw it last
      image.data.set(rgba, offset);
    }
  }
  const canvas = document.createElement("canvas");
  canvas.width = cols;
  canvas.height = rows;
  canvas.getContext("2d").putImageData(image, 0, 0);
  return canvas;
}

function drawMap() {
  const canvas = $("map");
  const ratio = window.devicePixelRatio || 1;
  canvas.width = Math.max(1, Math.round(canvas.clientWidth * ratio));
  canvas.height = Math.max(1, Math.round(canvas.clientHeight * ratio));
  const context = canvas.getContext("2d");
  context.setTransform(ratio, 0, 0, ratio, 0, 0);
  const width = canvas.clientWidth;
  const height = canvas.clientHeight;
  context.clearRect(0, 0, width, height);

  const bounds = worldBounds();
  const scale = Math.min(width / (bounds.maxX - bounds.minX), height / (bounds.maxY - bounds.minY));
  const offsetX = (width - (bounds.maxX - bounds.minX) * scale) / 2;
  const offsetY = (height - (bounds.maxY - bounds.minY) * scale) / 2;
  const px = (x) => offsetX + (x - bounds.minX) * scale;
  const py = (y) => height - offsetY - (y - bounds.minY) * scale; // north up

  const occupancy = view.occupancy;
  if (occupancy && occupancy.shape[0] > 0 && occupancy.shape[1] > 0) {
    const [rows, cols] = occupancy.shape;
    context.imageSmoothingEnabled = false;
    const top = occupancy.origin[1] + rows * occupancy.resolution_m;
    context.drawImage(
      occupancyImage(occupancy),
      px(occupancy.origin[0]), py(top),
      cols * occupancy.resolution_m * scale, rows * occupancy.resolution_m * scale,
    );
  }

  view.shapes = [];
  const nodes = view.graph.nodes;
  const byId = new Map(nodes.map((node) => [node.id, node]));
  context.font = "12px system-ui, sans-serif";
  context.textBaseline = "bottom";
  const labels = [];
  for (const node of nodes.filter((n) => n.kind === "fixture")) {
    const x = px(node.center[0] - node.extent[0] / 2);
    const y = py(node.center[1] + node.extent[1] / 2);
    const w = node.extent[0] * scale;
    const h = node.extent[1] * scale;
    context.globalAlpha = node.state === "confirmed" ? 0.45 : 0.2;
    context.fillStyle = "#3b6ea5";
    context.fillRect(x, y, w, h);
    context.globalAlpha = 1;
    context.strokeStyle = node.id === view.selected ? "#f08c00" : "#1c3d5a";
    context.lineWidth = node.id === view.selected ? 3 : 1.5;
    context.strokeRect(x, y, w, h);
    // Above the footprint, inside its top edge, or below it.
    const spots = [[x + 2, y - 2], [x + 2, y + 14], [x + 2, y + h + 14]];
    labels.push({ node, color: "#1c3d5a", spots });
    view.shapes.push({ id: node.id, kind: "fixture", x, y, w, h });
  }
  for (const node of nodes.filter((n) => n.kind !== "fixture")) {
    const x = px(node.center[0]);
    const y = py(node.center[1]);
    const parent = node.parent && byId.get(node.parent);
    if (parent) {
      context.strokeStyle = "rgba(217, 72, 15, 0.5)";
      context.lineWidth = 1;
      context.beginPath();
      context.moveTo(x, y);
      context.lineTo(px(parent.center[0]), py(parent.center[1]));
      context.stroke();
    }
    context.globalAlpha = node.state === "confirmed" ? 1 : 0.4;
    context.fillStyle = "#d9480f";
    context.beginPath();
    context.arc(x, y, OBJECT_RADIUS_PX, 0, 2 * Math.PI);
    context.fill();
    context.globalAlpha = 1;
    if (node.id === view.selected) {
      context.strokeStyle = "#f08c00";
      context.lineWidth = 3;
      context.stroke();
    }
    const r = OBJECT_RADIUS_PX + 2;
    // Right of the dot, above or below its centre, else left of it.
    const spots = [[x + r, y - 2], [x + r, y + 14], [x - r, y - 2, "right"], [x - r, y + 14, "right"]];
    labels.push({ node, color: "#212529", spots });
    view.shapes.push({ id: node.id, kind: "object", x: x - r, y: y - r, w: 2 * r, h: 2 * r });
  }
  const boxes = drawLabels(context, labels, width, height);
  canvas.dataset.nodes = String(nodes.length);
  canvas.dataset.labels = String(boxes.length);
  canvas.dataset.labelBoxes = JSON.stringify(boxes.map((b) => [b.x, b.y, b.w, b.h]));
  const bar = drawScaleBar(context, scale, height);
  canvas.dataset.scaleBar = bar.text;
  canvas.dataset.scaleBarPx = bar.px.toFixed(1);
  canvas.dataset.pxPerM = scale.toFixed(3);
}

const LABEL_HEIGHT_PX = 13;
const overlaps = (a, b) => a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;

// Labels never cover one another: each takes the first of its spots (x, y of the text's
// baseline, and its alignment) that is inside the map and clear of the labels already drawn,
// or is left out (the track list names every track). The selected track's label goes first,
// then confirmed tracks, fixtures before objects.
function drawLabels(context, labels, width, height) {
  const rank = ({ node }) => (node.id === view.selected ? 0 : 1) * 4
    + (node.state === "confirmed" ? 0 : 2) + (node.kind === "fixture" ? 0 : 1);
  const boxes = [];
  for (const label of [...labels].sort((a, b) => rank(a) - rank(b))) {
    const w = context.measureText(label.node.label).width + 2;
    for (const [x, y, align = "left"] of label.spots) {
      const box = { x: align === "right" ? x - w : x, y: y - LABEL_HEIGHT_PX, w, h: LABEL_HEIGHT_PX };
      const inside = box.x >= 0 && box.y >= 0 && box.x + w <= width && y <= height;
      if (!inside || boxes.some((other) => overlaps(other, box))) continue;
      context.fillStyle = label.color;
      context.fillText(label.node.label, box.x, y);
      boxes.push(box);
      break;
    }
  }
  return boxes;
}

// A scale bar in the bottom-left corner: the longest 1, 2 or 5 times a power of ten metres
// that fits in 120 pixels.
function drawScaleBar(context, pxPerM, height) {
  const maxPx = 120;
  let metres = 10 ** Math.floor(Math.log10(maxPx / pxPerM));
  for (const step of [5, 2]) {
    if (metres * step * pxPerM <= maxPx) {
      metres *= step;
      break;
    }
  }
  const px = metres * pxPerM;
  const text = metres >= 1 ? `${metres} m` : `${Math.round(metres * 100)} cm`;
  const x = 10;
  const y = height - 10;
  context.fillStyle = "rgba(255, 255, 255, 0.8)";
  context.fillRect(x - 4, y - 20, px + 8, 24);
  context.strokeStyle = "#212529";
  context.lineWidth = 2;
  context.beginPath();
  context.moveTo(x, y - 6);
  context.lineTo(x, y);
  context.lineTo(x + px, y);
  context.lineTo(x + px, y - 6);
  context.stroke();
  context.fillStyle = "#212529";
  context.fillText(text, x + 2, y - 4);
  return { text, px };
}

function trackAt(event) {
  const rect = $("map").getBoundingClientRect();
  const x = event.clientX - rect.left;
  const y = event.clientY - rect.top;
  const inside = (s) => x >= s.x && x <= s.x + s.w && y >= s.y && y <= s.y + s.h;
  // Objects sit on fixtures: they win a click on both.
  const hit = view.shapes.find((s) => s.kind === "object" && inside(s))
    || view.shapes.find((s) => s.kind === "fixture" && inside(s));
  return hit ? hit.id : null;
}

// --- one track -------------------------------------------------------------------------------

// --- questions: the objects of a class, at the seq shown ---------------------------------------

async function findObjects(label) {
  const results = $("search-results");
  if (!view.sceneId || !label) {
    results.replaceChildren();
    return;
  }
  const seq = view.seq;
  const query = new URLSearchParams({ label, as_of: String(seq), limit: "50" });
  const page = await api(scenePath(`/objects?${query}`));
  results.dataset.seq = String(page.seq);
  if (!page.objects.length) {
    results.replaceChildren(el("li", { className: "hint" }, `No ${label} at seq ${page.seq}.`));
    return;
  }
  results.replaceChildren(...page.objects.map((object) => el(
    "li",
    { dataset: { track: object.track_id }, onclick: () => selectTrack(object.track_id) },
    `${object.label} `,
    el("span", { className: "track-id" }, `${object.track_id} `),
    el("span", { className: "state" }, `${object.state} p=${fixed(object.p_exist)}`),
    object.parent ? ` on ${object.parent_label} (${object.parent})` : " on no fixture",
    object.last_observed_frame ? ` · last seen in ${object.last_observed_frame}` : "",
  )));
}

async function selectTrack(trackId) {
  view.selected = trackId;
  for (const item of $("tracks").children) {
    item.classList.toggle("selected", item.dataset.track === trackId);
  }
  if (view.graph) drawMap();
  await showTrack(trackId).catch(failed);
}

async function showTrack(trackId, ticket = view.renderTicket) {
  const [belief, explanation] = await Promise.all([
    api(scenePath(`/tracks/${encodeURIComponent(trackId)}?as_of=${view.seq}`)).catch((error) => {
      if (error instanceof ApiError && error.status === 404) return null;
      throw error;
    }),
    api(scenePath(`/tracks/${encodeURIComponent(trackId)}/explain`)),
  ]);
  if (ticket !== view.renderTicket || view.selected !== trackId) return;
  const rows = belief
    ? [
        ["label", belief.label],
        ["kind", belief.kind],
        ["state", belief.state],
        ["p_exist", fixed(belief.p_exist, 3)],
        ["log-odds", fixed(belief.existence_logodds, 3)],
        ["classes", topClasses(belief.class_probabilities)],
        ["center", vector(belief.center)],
        ["extent", vector(belief.extent)],
        ["parent", belief.parent ? labelOf(belief.parent) : "-"],
        ["parents", topClasses(belief.parent_probabilities)],
        ["last seen", belief.last_observed_frame || "-"],
        ["batches seen", belief.batches_observed],
        ["visible misses", belief.visible_misses],
      ]
    : [["belief", `no such track at seq ${view.seq}`]];
  const misses = explanation.removal
    ? el(
        "ol",
        {},
        ...explanation.removal.visible_misses.map((miss) =>
          el("li", {}, `seq ${miss.seq} frame ${miss.frame_id}: ${miss.samples_passed} samples, p_exist ${fixed(miss.p_exist_after, 3)}`),
        ),
      )
    : null;
  $("track-detail").replaceChildren(
    el("h3", {}, `${trackId} at seq ${belief ? belief.seq : view.seq}`),
    el("dl", {}, ...rows.flatMap(([name, value]) => [el("dt", {}, name), el("dd", {}, value)])),
    el("h3", {}, "Explanation"),
    el("p", { id: "explanation", className: "summary", dataset: { state: explanation.state } }, explanation.summary),
    misses,
    el("p", { className: "hint" }, `${explanation.visible_misses.length} visible misses since it was last seen`),
  );
}

// --- verification --------------------------------------------------------------------------

async function loadVerifications() {
  const { verifications } = await api(scenePath("/verifications"));
  const list = $("verifications");
  if (!verifications.length) {
    list.replaceChildren(el("li", { className: "hint" }, "Nothing waits for a verdict."));
    return;
  }
  list.replaceChildren(
    ...verifications.map((item) =>
      el(
        "li",
        { dataset: { track: item.track_id, label: item.label } },
        el("strong", { title: "show this track", onclick: () => selectTrack(item.track_id) }, item.label),
        ` ${item.track_id} `,
        el("span", { className: "state" }, `candidates: ${topClasses(item.candidates)}; frame ${item.best_frame || "-"}`),
        el(
          "div",
          { className: "verification-actions" },
          el("button", { type: "button", className: "confirm", onclick: () => verdict(item, "confirm") }, "Confirm"),
          el("button", { type: "button", className: "reject", onclick: () => verdict(item, "reject") }, "Reject"),
        ),
      ),
    ),
  );
}

async function verdict(item, answer) {
  try {
    const body = { verdict: answer, source: "viewer" };
    if (item.best_frame) body.frame_id = item.best_frame;
    const result = await api(scenePath(`/tracks/${encodeURIComponent(item.track_id)}/verification`), {
      method: "POST",
      body,
    });
    say(`${item.label} ${item.track_id}: ${answer}ed, now ${result.state}`, true);
    const scene = await api(scenePath());
    setHead(scene.head_seq, true);
    await Promise.all([showSeq(view.head), loadVerifications()]);
  } catch (error) {
    failed(error);
  }
}

// --- wiring --------------------------------------------------------------------------------

let sliderTimer = null;

function start() {
  $("token").value = token();
  $("search-form").addEventListener("submit", (event) => {
    event.preventDefault();
    findObjects($("search").value.trim()).catch(failed);
  });
  $("token-form").addEventListener("submit", (event) => {
    event.preventDefault();
    sessionStorage.setItem("pbdag-token", $("token").value.trim());
    loadScenes().catch(failed);
  });
  $("scene-select").addEventListener("change", (event) => openScene(event.target.value).catch(failed));
  $("seq").addEventListener("input", (event) => {
    $("seq-label").textContent = event.target.value;
    $("follow").checked = Number(event.target.value) === view.head;
    if (!$("follow").checked) stopFeed();
    else if (!feed.controller) startFeed();
    clearTimeout(sliderTimer);
    sliderTimer = setTimeout(() => showSeq(Number(event.target.value)), 120);
  });
  $("follow").addEventListener("change", (event) => {
    if (!event.target.checked || !view.sceneId) {
      stopFeed();
      return;
    }
    setHead(view.head, true);  // back to the newest seq now, then to every new one (the feed)
    showSeq(view.head).catch(failed);
    startFeed();
  });
  $("show-all").addEventListener("change", () => showSeq(view.seq));
  $("events-earlier").addEventListener("click", () => pageEvents(-1));
  $("events-later").addEventListener("click", () => pageEvents(1));
  $("map").addEventListener("click", (event) => {
    const trackId = trackAt(event);
    if (trackId) selectTrack(trackId);
  });
  window.addEventListener("resize", () => view.graph && drawMap());
  setInterval(pollHead, HEAD_POLL_MS);
  loadScenes().catch(failed);
}

start();
