//! The web page (issue 22): `GET /` is a single page over the API (skills with every filter,
//! a skill's phases, forces, contacts in 3D and nearest skills, replays on any hand, sessions,
//! hands), `GET /docs` renders the OpenAPI document, `GET /assets/...` the page's files.
//!
//! Everything is in the binary (`include_bytes!` of `api/web/`): no build step, no Node, no
//! network at run time. The page is plain ES modules; the libraries it uses (three.js, uPlot,
//! Swagger UI) are vendored from their npm packages with their licences
//! (`api/web/vendor/VENDORED.md`). Any other path outside `/api/` and `/healthz` answers a
//! not-found page in HTML; the API's own paths keep their problem+json errors.

use axum::extract::Path;
use axum::http::{header, HeaderValue, StatusCode, Uri};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;

use super::error::Problem;

/// One embedded file: its path under `/assets/`, media type and bytes.
struct Asset {
    path: &'static str,
    media_type: &'static str,
    bytes: &'static [u8],
}

macro_rules! asset {
    ($path:literal, $media:expr) => {
        Asset {
            path: $path,
            media_type: $media,
            bytes: include_bytes!(concat!("../../web/", $path)),
        }
    };
}

const JS: &str = "text/javascript; charset=utf-8";
const CSS: &str = "text/css; charset=utf-8";
const HTML: &str = "text/html; charset=utf-8";
const TEXT: &str = "text/plain; charset=utf-8";

/// Every file under `/assets/`.
static ASSETS: &[Asset] = &[
    asset!("app.js", JS),
    asset!("api.js", JS),
    asset!("dom.js", JS),
    asset!("plot.js", JS),
    asset!("scene.js", JS),
    asset!("docs.js", JS),
    asset!("style.css", CSS),
    asset!("vendor/three/three.module.js", JS),
    asset!("vendor/three/three.core.js", JS),
    asset!("vendor/three/LICENSE", TEXT),
    asset!("vendor/uplot/uPlot.esm.js", JS),
    asset!("vendor/uplot/uPlot.min.css", CSS),
    asset!("vendor/uplot/LICENSE", TEXT),
    asset!("vendor/swagger-ui/swagger-ui-bundle.js", JS),
    asset!("vendor/swagger-ui/swagger-ui.css", CSS),
    asset!("vendor/swagger-ui/LICENSE", TEXT),
    asset!("vendor/swagger-ui/NOTICE", TEXT),
    asset!("vendor/swagger-ui/swagger-ui-bundle.js.LICENSE.txt", TEXT),
    asset!("vendor/VENDORED.md", TEXT),
];

static INDEX_HTML: &[u8] = include_bytes!("../../web/index.html");
static DOCS_HTML: &[u8] = include_bytes!("../../web/docs.html");
static NOT_FOUND_HTML: &[u8] = include_bytes!("../../web/not-found.html");

/// The page's content security policy: its own files only, no inline script; inline styles
/// are allowed (uPlot and Swagger UI set them).
const CSP: &str = "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; \
                   img-src 'self' data: blob:; connect-src 'self'; object-src 'none'; \
                   base-uri 'none'; frame-ancestors 'none'";

/// The page's routes (no state, not in the OpenAPI document: they are not the API).
pub fn router<S: Clone + Send + Sync + 'static>() -> Router<S> {
    Router::new()
        .route("/", get(|| async { page(StatusCode::OK, INDEX_HTML) }))
        .route("/docs", get(|| async { page(StatusCode::OK, DOCS_HTML) }))
        .route("/assets/{*path}", get(asset))
}

fn page(status: StatusCode, html: &'static [u8]) -> Response {
    let mut r = (status, html).into_response();
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(HTML));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    r
}

async fn asset(Path(path): Path<String>) -> Response {
    let Some(a) = ASSETS.iter().find(|a| a.path == path) else {
        return page(StatusCode::NOT_FOUND, NOT_FOUND_HTML);
    };
    let mut r = a.bytes.into_response();
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(a.media_type));
    // The files change only with the binary; revalidating costs one small request each.
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    r
}

/// The answer to a path no route takes: a problem under the API's paths (`/api/...`,
/// `/healthz`), the HTML not-found page anywhere else.
pub async fn not_found(uri: Uri) -> Response {
    let p = uri.path();
    if p == "/api" || p.starts_with("/api/") || p.starts_with("/healthz") {
        return Problem::not_found("no such route; the API is described at /api/v1/openapi.json")
            .into_response();
    }
    page(StatusCode::NOT_FOUND, NOT_FOUND_HTML)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_asset_has_bytes_and_a_unique_path() {
        let mut seen = std::collections::BTreeSet::new();
        for a in ASSETS {
            assert!(!a.bytes.is_empty(), "{}", a.path);
            assert!(seen.insert(a.path), "{} twice", a.path);
        }
    }
}
