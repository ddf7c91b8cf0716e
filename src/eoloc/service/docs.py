"""The OpenAPI page (/docs: Swagger UI) served from files installed with eoloc, never from a CDN:
on a ground station without internet it is not blank. The assets are those the fastapi-offline
package ships (Swagger UI 5, which reads OpenAPI 3.1 as FastAPI writes it), mounted at
/docs-assets. No /redoc: ReDoc's page loads its badge from a CDN whatever it is told."""

from __future__ import annotations

from pathlib import Path

from fastapi import Request  # resolved from this module's names: the routes' annotations are strings here
from fastapi.responses import HTMLResponse

ASSETS_URL = "/docs-assets"


def assets_folder() -> Path:
    """Where the installed Swagger UI files are."""
    import fastapi_offline

    return Path(fastapi_offline.__file__).parent / "static"


def add_offline_docs(app) -> None:
    """/docs on ``app`` (created with docs_url=None, redoc_url=None), its script, style and icon
    from :func:`assets_folder`."""
    from fastapi.openapi.docs import get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
    from fastapi.staticfiles import StaticFiles

    app.mount(ASSETS_URL, StaticFiles(directory=str(assets_folder())), name="docs-assets")

    @app.get("/docs", include_in_schema=False)
    async def swagger_ui(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return get_swagger_ui_html(openapi_url=f"{root}{app.openapi_url}", title=f"{app.title} - Swagger UI",
                                   oauth2_redirect_url=app.swagger_ui_oauth2_redirect_url,
                                   swagger_js_url=f"{root}{ASSETS_URL}/swagger-ui-bundle.js",
                                   swagger_css_url=f"{root}{ASSETS_URL}/swagger-ui.css",
                                   swagger_favicon_url=f"{root}{ASSETS_URL}/favicon.png")

    @app.get(app.swagger_ui_oauth2_redirect_url, include_in_schema=False)
    async def swagger_ui_redirect() -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()
