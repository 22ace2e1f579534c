//! The game's HTTP side: a blocking `tiny_http` server on a few worker threads, the page embedded in
//! the binary, and the JSON routes over [`Game`].
//!
//! Routes: `GET /` (the page), `GET /api/world[?projection=i,j]` (the task as drawn), `GET /api/state` (runs, coverage,
//! players), `POST /api/start`, `POST /api/step`, `POST /api/finish` ([`Game`]'s methods of those
//! names). Every refusal is a JSON `{"error": message}` with a 4xx/5xx status; a request body is at most
//! [`MAX_BODY`] bytes; a handler that panicked answers 500 and the server keeps serving.

use super::game::{Game, PlayError};
use serde_json::{json, Value};
use std::io::Read;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// The page, with its script and style inline: nothing is fetched from elsewhere.
pub const PAGE: &str = include_str!("page/index.html");
/// Largest request body accepted (bytes).
pub const MAX_BODY: u64 = 64 * 1024;
/// Worker threads answering requests.
pub const WORKERS: usize = 4;

/// A running server: its address, and a way to stop it.
pub struct Served {
    pub addr: SocketAddr,
    server: Arc<tiny_http::Server>,
    workers: Vec<JoinHandle<()>>,
}

impl Served {
    /// Stops accepting requests and waits for the workers.
    pub fn stop(self) {
        for _ in &self.workers {
            self.server.unblock();
        }
        for w in self.workers {
            let _ = w.join();
        }
    }

    /// Serves until the process ends.
    pub fn wait(self) {
        for w in self.workers {
            let _ = w.join();
        }
    }
}

/// Serves `game` on `addr` (port 0: any free port).
pub fn serve(game: Game, addr: SocketAddr) -> Result<Served, String> {
    let server =
        tiny_http::Server::http(addr).map_err(|e| format!("cannot listen on {addr}: {e}"))?;
    let addr = server
        .server_addr()
        .to_ip()
        .ok_or_else(|| "the server has no IP address".to_string())?;
    let server = Arc::new(server);
    let game = Arc::new(Mutex::new(game));
    let workers = (0..WORKERS)
        .map(|_| {
            let (server, game) = (server.clone(), game.clone());
            std::thread::spawn(move || {
                while let Ok(req) = server.recv() {
                    answer(&game, req);
                }
            })
        })
        .collect();
    Ok(Served {
        addr,
        server,
        workers,
    })
}

fn answer(game: &Mutex<Game>, mut req: tiny_http::Request) {
    let method = req.method().clone();
    let (url, query) = match req.url().split_once('?') {
        Some((u, q)) => (u.to_string(), q.to_string()),
        None => (req.url().to_string(), String::new()),
    };
    let mut body = Vec::new();
    let read = req
        .as_reader()
        .take(MAX_BODY + 1)
        .read_to_end(&mut body)
        .map_err(|e| format!("cannot read the request: {e}"));
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        route(game, &method, &url, &query, read.map(|_| body))
    }))
    .unwrap_or_else(|_| {
        Err((
            500,
            "internal error: the request failed; the server keeps running".into(),
        ))
    });
    let response = match outcome {
        Ok(Reply::Page) => tiny_http::Response::from_string(PAGE)
            .with_header(header("Content-Type", "text/html; charset=utf-8"))
            .with_chunked_threshold(usize::MAX),
        Ok(Reply::Json(v)) => json_response(200, &v),
        Err((code, msg)) => json_response(code, &json!({ "error": msg })),
    };
    let _ = req.respond(response);
}

enum Reply {
    Page,
    Json(Value),
}

fn route(
    game: &Mutex<Game>,
    method: &tiny_http::Method,
    url: &str,
    query: &str,
    body: Result<Vec<u8>, String>,
) -> Result<Reply, (u16, String)> {
    use tiny_http::Method::{Get, Post};
    let lock = || game.lock().unwrap_or_else(|e| e.into_inner());
    match (method, url) {
        (Get, "/" | "/index.html") => Ok(Reply::Page),
        (Get, "/api/world") => {
            // `?projection=i,j`: the two state coordinates drawn (0-based); numbers or not, the game
            // checks them.
            let projection = query
                .split('&')
                .find_map(|kv| kv.strip_prefix("projection="))
                .map(|p| {
                    Value::Array(
                        p.split(',')
                            .map(|i| i.parse::<u64>().map_or(Value::Null, Value::from))
                            .collect(),
                    )
                });
            let w = lock().world(projection.as_ref());
            w.map(Reply::Json).map_err(|e| (status(&e), e.to_string()))
        }
        (Get, "/api/state") => Ok(Reply::Json(lock().state())),
        (Post, "/api/start" | "/api/step" | "/api/finish") => {
            let body = body.map_err(|e| (400, e))?;
            if body.len() as u64 > MAX_BODY {
                return Err((
                    413,
                    format!("the request body is larger than {MAX_BODY} bytes"),
                ));
            }
            let v: Value =
                serde_json::from_slice(&body).map_err(|e| (400, format!("malformed JSON: {e}")))?;
            let mut g = lock();
            let r = match url {
                "/api/start" => g.start(&v),
                "/api/step" => g.step(&v),
                _ => g.finish(&v),
            };
            r.map(Reply::Json).map_err(|e| (status(&e), e.to_string()))
        }
        (_, "/" | "/index.html" | "/api/world" | "/api/state") => {
            Err((405, format!("{url} answers GET only")))
        }
        (_, "/api/start" | "/api/step" | "/api/finish") => {
            Err((405, format!("{url} answers POST only")))
        }
        _ => Err((404, format!("no such page: {}", crate::text::excerpt(url)))),
    }
}

fn status(e: &PlayError) -> u16 {
    match e {
        PlayError::BadRequest(_) => 400,
        PlayError::UnknownSession(_) => 404,
        PlayError::Busy => 503,
        PlayError::Io(_) => 500,
    }
}

fn header(k: &str, v: &str) -> tiny_http::Header {
    tiny_http::Header::from_bytes(k.as_bytes(), v.as_bytes()).expect("a valid ASCII header")
}

fn json_response(code: u16, v: &Value) -> tiny_http::Response<std::io::Cursor<Vec<u8>>> {
    tiny_http::Response::from_data(serde_json::to_vec(v).unwrap_or_default())
        .with_status_code(code)
        .with_header(header("Content-Type", "application/json"))
        .with_header(header("Cache-Control", "no-store"))
        // The length is known: send it, never chunked (simple clients read to the end).
        .with_chunked_threshold(usize::MAX)
}
