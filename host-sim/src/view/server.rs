//! The view's HTTP server (axum on tokio): the page and its script and style (built into the
//! binary), `GET /snapshot`, `GET /state` (everything the page draws), `GET /events` (Server-Sent
//! Events: an `update` every [`TICK`] while something changed, events coalesced), and `POST
//! /control` (pause, resume, step, speed: for a source that can be paused, else 403).

use std::convert::Infallible;
use std::net::{IpAddr, SocketAddr, TcpListener};
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::{Query, State};
use axum::http::{StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Json as JsonBody};
use axum::routing::{get, post};
use serde::Deserialize;
use serde_json::{Value as Json, json};

use super::model::RING;
use super::source::{Control, SPEEDS, Shared, lock};

/// How often a page is sent what changed.
pub const TICK: Duration = Duration::from_millis(100);
/// Events in one update at most: past that, samples are thinned (coalesced).
pub const MAX_EVENTS: usize = 400;

const PAGE: &str = include_str!("page.html");
const SCRIPT: &str = include_str!("app.js");
const STYLE: &str = include_str!("style.css");

/// Listens on `bind`:`port` (0: a free port): one line saying why not (a port in use, an
/// address this machine does not have).
pub fn listen(bind: IpAddr, port: u16) -> Result<TcpListener, String> {
    let addr = SocketAddr::new(bind, port);
    TcpListener::bind(addr).map_err(|e| format!("cannot listen on {addr}: {e}"))
}

fn status(shared: &Shared) -> Json {
    match &shared.pace {
        Some(p) => {
            let (paused, speed, lag_ms, late_ms) = p.status();
            json!({
                "controllable": true, "paused": paused, "speed": speed,
                "lag_ms": lag_ms, "late_ms": late_ms,
            })
        }
        None => json!({ "controllable": false }),
    }
}

async fn snapshot(State(shared): State<Arc<Shared>>) -> JsonBody<Json> {
    JsonBody(lock(&shared.view).snapshot())
}

/// Everything the page draws, with the newest `max` events at most (samples thinned past it).
fn whole_state(shared: &Shared, max: usize) -> Json {
    let (mission, (mut update, seq, errors)) = {
        let view = lock(&shared.view);
        (view.mission(), view.update(0, 0, max))
    };
    if let Some(o) = update.as_object_mut() {
        o.insert("mission".into(), mission);
        o.insert("source".into(), json!(shared.source));
        o.insert("status".into(), status(shared));
        o.insert("seq".into(), json!(seq));
        o.insert("error_seq".into(), json!(errors));
    }
    update
}

async fn state(State(shared): State<Arc<Shared>>) -> JsonBody<Json> {
    JsonBody(whole_state(&shared, RING))
}

/// The page with the state at the moment it is asked for built in: it draws at once, before
/// its live updates start.
async fn page(State(shared): State<Arc<Shared>>) -> Html<String> {
    // "</" escaped: the JSON cannot end its script element.
    let state = whole_state(&shared, MAX_EVENTS)
        .to_string()
        .replace("</", "<\\/");
    Html(PAGE.replace(
        "<!--STATE-->",
        &format!("<script id=\"initial\" type=\"application/json\">{state}</script>"),
    ))
}

/// Where a page's stream starts: after event `since` and error `errors`.
#[derive(Deserialize)]
struct Since {
    #[serde(default)]
    since: u64,
    #[serde(default)]
    errors: u64,
}

async fn events(
    State(shared): State<Arc<Shared>>,
    Query(at): Query<Since>,
) -> Sse<impl futures_util::Stream<Item = Result<Event, Infallible>>> {
    let start = (shared, at.since, at.errors, Json::Null);
    let stream = futures_util::stream::unfold(start, |(shared, since, errors, last)| async move {
        loop {
            tokio::time::sleep(TICK).await;
            let (mut update, seq, error_seq) = lock(&shared.view).update(since, errors, MAX_EVENTS);
            let st = status(&shared);
            if seq == since && error_seq == errors && st == last {
                continue;
            }
            if let Some(o) = update.as_object_mut() {
                o.insert("status".into(), st.clone());
                o.insert("seq".into(), json!(seq));
                o.insert("error_seq".into(), json!(error_seq));
            }
            let event = Event::default().event("update").data(update.to_string());
            return Some((Ok(event), (shared, seq, error_seq, st)));
        }
    });
    Sse::new(stream).keep_alive(KeepAlive::new().interval(Duration::from_secs(10)))
}

/// A command of the page's controls.
#[derive(Deserialize)]
struct Command {
    r#do: String,
    x: Option<f64>,
}

async fn control(State(shared): State<Arc<Shared>>, Query(c): Query<Command>) -> impl IntoResponse {
    let Some(pace) = &shared.pace else {
        return (
            StatusCode::FORBIDDEN,
            "this source cannot be paused: it is a robot's own stream\n",
        );
    };
    let command = match (c.r#do.as_str(), c.x) {
        ("pause", _) => Control::Pause,
        ("resume", _) => Control::Resume,
        ("step", _) => Control::Step,
        ("speed", Some(x)) if (SPEEDS.0..=SPEEDS.1).contains(&x) => Control::Speed(x),
        _ => {
            return (
                StatusCode::BAD_REQUEST,
                "do=pause, resume, step, or speed with x from 0.01 to 10000\n",
            );
        }
    };
    pace.control(command);
    (StatusCode::OK, "ok\n")
}

/// The page's routes.
pub fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(page))
        .route(
            "/app.js",
            get(|| async {
                (
                    [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
                    SCRIPT,
                )
            }),
        )
        .route(
            "/style.css",
            get(|| async { ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], STYLE) }),
        )
        .route("/snapshot", get(snapshot))
        .route("/state", get(state))
        .route("/events", get(events))
        .route("/control", post(control))
        .with_state(shared)
}

/// Serves the view on `listener` until the process is stopped: one line when the server
/// cannot run.
pub fn serve(listener: TcpListener, shared: Arc<Shared>) -> Result<(), String> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the server: {e}"))?;
    runtime.block_on(async move {
        listener
            .set_nonblocking(true)
            .map_err(|e| format!("the server's socket: {e}"))?;
        let listener = tokio::net::TcpListener::from_std(listener)
            .map_err(|e| format!("the server's socket: {e}"))?;
        axum::serve(listener, router(shared))
            .await
            .map_err(|e| format!("the server stopped: {e}"))
    })
}
