#!/usr/bin/env bash
# Fetch the browser assets the service serves itself (offline /docs) from the npm registry, at a
# pinned version checked against its sha256, into service/static/vendor/. `make vendor` runs it;
# the result is committed, so neither a build nor the service ever needs the network.
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGE=swagger-ui-dist
VERSION=5.35.0
SHA256=1b8e891893404ea4c3558b6a87e2a3e494e7eedba41168c2ece5800a391a6ea6  # of the npm tarball
FILES=(swagger-ui-bundle.js swagger-ui-bundle.js.LICENSE.txt swagger-ui.css favicon-32x32.png LICENSE NOTICE)
DEST="service/static/vendor/$PACKAGE"

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
echo "$PACKAGE@$VERSION from $(npm view "$PACKAGE@$VERSION" dist.tarball)"
(cd "$work" && npm pack --silent "$PACKAGE@$VERSION" >/dev/null)
tarball="$work/$PACKAGE-$VERSION.tgz"
echo "$SHA256  $tarball" | sha256sum --check --quiet -
tar -xzf "$tarball" -C "$work"
rm -rf "$DEST"
mkdir -p "$DEST"
for name in "${FILES[@]}"; do
  cp "$work/package/$name" "$DEST/$name"
done
printf '%s %s\nnpm tarball sha256 %s\n' "$PACKAGE" "$VERSION" "$SHA256" >"$DEST/VERSION"
echo "copied ${#FILES[@]} files into $DEST"
