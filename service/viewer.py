"""Browser pages served from the package: the scene viewer at /viewer and offline /docs.

Every asset is a file under service/static/ (Swagger UI is vendored by scripts/vendor-assets.sh),
so neither page loads anything from another host. The pages and their assets hold no scene
data and need no token (security.OPEN_PREFIXES): a browser on the LAN must load the viewer
before its user can type a token, which the viewer then sends with every API request.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from starlette.responses import FileResponse, HTMLResponse
from starlette.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send

STATIC_DIR = Path(__file__).resolve().parent / "static"
STATIC_PREFIX = "/static"
VIEWER_PATH = "/viewer"
SWAGGER = f"{STATIC_PREFIX}/vendor/swagger-ui-dist"
# The viewer's pages: scripts, styles, requests and images from this origin only.
VIEWER_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'self'; form-action 'self'; "
    "frame-ancestors 'self'"
)


class ViewerHeaders:
    """Pure ASGI middleware: the Content-Security-Policy on the viewer's page and files."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Add the headers to responses under /viewer and /static/viewer/."""
        path = str(scope.get("path", ""))
        if scope["type"] != "http" or not (
            path == VIEWER_PATH or path.startswith(f"{STATIC_PREFIX}/viewer/")
        ):
            await self.app(scope, receive, send)
            return

        async def send_with_policy(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                headers.append((b"content-security-policy", VIEWER_CSP.encode()))
                headers.append((b"x-content-type-options", b"nosniff"))
                message["headers"] = headers
            await send(message)

        await self.app(scope, receive, send_with_policy)


def install_pages(app: FastAPI) -> None:
    """Serve /static, /viewer and /docs (the app is created with docs_url=None, redoc_url=None)."""
    app.mount(STATIC_PREFIX, StaticFiles(directory=STATIC_DIR), name="static")
    openapi_url = app.openapi_url or "/openapi.json"
    title = f"{app.title} - API"

    @app.get("/docs", include_in_schema=False)
    def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=openapi_url,
            title=title,
            swagger_js_url=f"{SWAGGER}/swagger-ui-bundle.js",
            swagger_css_url=f"{SWAGGER}/swagger-ui.css",
            swagger_favicon_url=f"{SWAGGER}/favicon-32x32.png",
            swagger_ui_parameters={"validatorUrl": None},  # no badge from a validator service
        )

    @app.get(VIEWER_PATH, include_in_schema=False)
    def viewer() -> FileResponse:
        return FileResponse(STATIC_DIR / "viewer" / "index.html", media_type="text/html")

    app.add_middleware(ViewerHeaders)
