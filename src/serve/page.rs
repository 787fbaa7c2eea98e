//! The status page at `/`: every rig and its state, the running test's
//! progress with a live plot, abort, emergency stop and reset, and the
//! records with their reports, plots and downloads. It is one HTML file,
//! a script, a style sheet and the vendored plotting library (uPlot,
//! brought in by `scripts/vendor-web.sh`), all embedded in the binary: no
//! network at run time, no CDN.
//!
//! These files hold no data and are served without the token (any other
//! path under `/ui/` is the API's and needs it); the page
//! asks for the token once (kept in the browser tab's session storage)
//! and sends it with every API call, which needs it like any other.

use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;

/// The page's files: (name under `/ui/`, content type, content).
const FILES: [(&str, &str, &str); 5] = [
    (
        "app.js",
        "text/javascript; charset=utf-8",
        include_str!("page/app.js"),
    ),
    (
        "style.css",
        "text/css; charset=utf-8",
        include_str!("page/style.css"),
    ),
    (
        "uplot.js",
        "text/javascript; charset=utf-8",
        include_str!("page/vendor/uPlot.iife.min.js"),
    ),
    (
        "uplot.css",
        "text/css; charset=utf-8",
        include_str!("page/vendor/uPlot.min.css"),
    ),
    (
        "LICENSE-uPlot",
        "text/plain; charset=utf-8",
        include_str!("page/vendor/LICENSE-uPlot"),
    ),
];

const INDEX: &str = include_str!("page/index.html");

/// The page's routes: `/` and `/ui/FILE` for each of its files, each
/// route its own (any other path is the API's, token and all).
pub fn router<S: Clone + Send + Sync + 'static>() -> Router<S> {
    let mut router = Router::new().route(
        "/",
        get(|| async { page_answer("text/html; charset=utf-8", INDEX) }),
    );
    for (name, content_type, body) in FILES {
        router = router.route(
            &format!("/ui/{name}"),
            get(move || async move { page_answer(content_type, body) }),
        );
    }
    router
}

fn page_answer(content_type: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
            // The page loads nothing from elsewhere and is not framed.
            (
                header::CONTENT_SECURITY_POLICY,
                "default-src 'self'; img-src 'self' blob: data:; style-src 'self' 'unsafe-inline'; \
                 frame-ancestors 'none'",
            ),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        body,
    )
        .into_response()
}
