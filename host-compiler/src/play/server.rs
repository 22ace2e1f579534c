//! The game's HTTP side: a small HTTP/1.1 server on std's `TcpListener` (the request head parsed by
//! `httparse`), the page embedded in the binary, and the JSON routes over [`Game`].
//!
//! Routes: `GET /` (the page), `GET /api/world[?projection=i,j]` (the task as drawn), `GET /api/state` (runs, coverage,
//! players), `POST /api/start`, `POST /api/step`, `POST /api/finish` ([`Game`]'s methods of those
//! names). Every refusal is a JSON `{"error": message}` with a 4xx/5xx status; a request body is at most
//! [`MAX_BODY`] bytes; a handler that panicked answers 500 and the server keeps serving.
//!
//! **Bounded.** One request per connection (`Connection: close`). At most [`MAX_CONNECTIONS`]
//! connections are served at once, each on a thread of its own with a small stack; a connection beyond
//! that, or one whose thread cannot be started, is answered 503 at once (and its request read and
//! dropped for up to [`LINGER`], so the answer is not lost to a reset). A connection must send its
//! request within [`REQUEST_TIMEOUT`], so idle connections free their place. An accept that fails (no
//! descriptors left) is retried after a pause; nothing here panics or stops accepting, so the server
//! answers normally again once the load drops. (`tiny_http`, used before, spawns a thread per connection
//! without bound, and its accept loop ends on the first failed spawn or accept.)

use super::game::{Game, PlayError};
use serde_json::{json, Value};
use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The page, with its script and style inline: nothing is fetched from elsewhere.
pub const PAGE: &str = include_str!("page/index.html");
/// Largest request body accepted (bytes).
pub const MAX_BODY: u64 = 64 * 1024;
/// Largest request head (request line and headers), bytes.
pub const MAX_HEAD: usize = 16 * 1024;
/// Connections served at once (one thread each); more are answered 503.
pub const MAX_CONNECTIONS: usize = 64;
/// Time a connection has to send its whole request.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(2);
/// Time a refused connection is kept open to read (and drop) its request after the 503.
pub const LINGER: Duration = Duration::from_millis(500);
/// Most refused connections lingering at once; beyond, one is closed without an answer.
const MAX_LINGERING: usize = 1024;
/// Stack of a connection's thread (the handlers are shallow; the game's work is bounded).
const STACK: usize = 512 * 1024;
/// Pause of the accept loop when nothing is pending.
const POLL: Duration = Duration::from_millis(2);

/// A running server: its address, and a way to stop it.
pub struct Served {
    pub addr: SocketAddr,
    stop: Arc<AtomicBool>,
    acceptor: JoinHandle<()>,
}

impl Served {
    /// Stops accepting connections and waits for the accept loop (requests in progress finish on their
    /// own threads).
    pub fn stop(self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = self.acceptor.join();
    }

    /// Serves until the process ends.
    pub fn wait(self) {
        let _ = self.acceptor.join();
    }
}

/// Serves `game` on `addr` (port 0: any free port).
pub fn serve(game: Game, addr: SocketAddr) -> Result<Served, String> {
    let listener = TcpListener::bind(addr).map_err(|e| format!("cannot listen on {addr}: {e}"))?;
    let addr = listener
        .local_addr()
        .map_err(|e| format!("the server has no address: {e}"))?;
    listener
        .set_nonblocking(true)
        .map_err(|e| format!("cannot listen on {addr}: {e}"))?;
    let game = Arc::new(Mutex::new(game));
    let stop = Arc::new(AtomicBool::new(false));
    let acceptor = {
        let stop = stop.clone();
        std::thread::Builder::new()
            .name("play-accept".into())
            .spawn(move || accept_loop(&listener, &game, &stop))
            .map_err(|e| format!("cannot start the server: {e}"))?
    };
    Ok(Served {
        addr,
        stop,
        acceptor,
    })
}

/// Releases a connection's place when its thread ends (or never starts).
struct Slot(Arc<AtomicUsize>);

impl Drop for Slot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// A refused connection: answered, its write side shut, read and dropped until `until` or its end.
struct Lingering {
    stream: TcpStream,
    until: Instant,
}

fn accept_loop(listener: &TcpListener, game: &Arc<Mutex<Game>>, stop: &AtomicBool) {
    let active = Arc::new(AtomicUsize::new(0));
    let mut lingering: VecDeque<Lingering> = VecDeque::new();
    while !stop.load(Ordering::SeqCst) {
        let mut idle = true;
        match listener.accept() {
            Ok((stream, _)) => {
                idle = false;
                if let Some(busy) = admit(stream, game, &active) {
                    refuse(busy, &mut lingering);
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted => {}
            // No descriptors or memory left, or a connection reset before it was accepted: pause, and
            // accept again once the load drops.
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
        let now = Instant::now();
        lingering.retain_mut(|l| {
            let mut buf = [0u8; 4096];
            loop {
                match l.stream.read(&mut buf) {
                    Ok(0) => return false,
                    Ok(_) => continue,
                    Err(e) if e.kind() == ErrorKind::WouldBlock => return now < l.until,
                    Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                    Err(_) => return false,
                }
            }
        });
        if idle {
            std::thread::sleep(POLL);
        }
    }
}

/// Serves the connection on a thread of its own if there is a place and the thread starts; else hands it
/// back to be refused.
fn admit(
    stream: TcpStream,
    game: &Arc<Mutex<Game>>,
    active: &Arc<AtomicUsize>,
) -> Option<TcpStream> {
    if active.fetch_add(1, Ordering::SeqCst) >= MAX_CONNECTIONS {
        active.fetch_sub(1, Ordering::SeqCst);
        return Some(stream);
    }
    let slot = Slot(active.clone());
    // Kept to answer 503 should the thread not start (the closure, and the stream in it, is dropped).
    let spare = stream.try_clone().ok();
    let game = game.clone();
    let started = std::thread::Builder::new()
        .name("play-conn".into())
        .stack_size(STACK)
        .spawn(move || {
            let _slot = slot;
            connection(&game, stream);
        });
    match started {
        Ok(_) => None,
        Err(_) => spare,
    }
}

/// Answers 503 and leaves the connection to linger (module doc).
fn refuse(mut stream: TcpStream, lingering: &mut VecDeque<Lingering>) {
    let body = json!({
        "error": format!(
            "the server is busy ({MAX_CONNECTIONS} connections at once); try again in a moment"
        )
    })
    .to_string();
    let head = format!(
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\
         Retry-After: 1\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    );
    let _ = stream.set_nonblocking(true);
    // A fresh socket's send buffer takes the few hundred bytes at once.
    let _ = stream.write_all(head.as_bytes());
    let _ = stream.write_all(body.as_bytes());
    let _ = stream.shutdown(Shutdown::Write);
    if lingering.len() >= MAX_LINGERING {
        lingering.pop_front();
    }
    lingering.push_back(Lingering {
        stream,
        until: Instant::now() + LINGER,
    });
}

/// A request as read from the connection.
struct Request {
    method: String,
    url: String,
    body: Result<Vec<u8>, String>,
}

/// Reads one request within [`REQUEST_TIMEOUT`], answers it, and closes.
fn connection(game: &Mutex<Game>, mut stream: TcpStream) {
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_nodelay(true);
    let deadline = Instant::now() + REQUEST_TIMEOUT;
    let (code, reply) = match read_request(&mut stream, deadline) {
        Ok(req) => answer(game, req),
        Err(None) => return, // closed, or silent until the deadline: nothing to answer
        Err(Some((code, msg))) => (code, Reply::Json(json!({ "error": msg }))),
    };
    let _ = stream.set_write_timeout(Some(REQUEST_TIMEOUT));
    let _ = write_response(&mut stream, code, &reply);
    let _ = stream.shutdown(Shutdown::Write);
    // Read what is left of the request (a body too large), so that closing does not reset the answer.
    let _ = stream.set_read_timeout(Some(Duration::from_millis(200)));
    let mut sink = [0u8; 4096];
    let mut drained = 0usize;
    while drained < 4 * MAX_BODY as usize {
        match stream.read(&mut sink) {
            Ok(0) | Err(_) => break,
            Ok(k) => drained += k,
        }
    }
}

/// Reads from `stream` until the deadline (`Err(None)`: the peer closed or the time ran out).
fn read_some(stream: &mut TcpStream, buf: &mut [u8], deadline: Instant) -> Result<usize, ()> {
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(());
        }
        let _ = stream.set_read_timeout(Some(left));
        match stream.read(buf) {
            Ok(0) => return Err(()),
            Ok(k) => return Ok(k),
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(_) => return Err(()),
        }
    }
}

type Refusal = Option<(u16, String)>;

/// The request line, headers and body; a malformed or oversized request is `Err(Some((status, why)))`.
fn read_request(stream: &mut TcpStream, deadline: Instant) -> Result<Request, Refusal> {
    let mut buf: Vec<u8> = Vec::with_capacity(1024);
    let mut chunk = [0u8; 4096];
    loop {
        let k = read_some(stream, &mut chunk, deadline).map_err(|()| {
            if buf.is_empty() {
                None
            } else {
                Some((408, "the request did not arrive in time".to_string()))
            }
        })?;
        buf.extend_from_slice(&chunk[..k]);
        let mut headers = [httparse::EMPTY_HEADER; 64];
        let mut req = httparse::Request::new(&mut headers);
        match req.parse(&buf) {
            Ok(httparse::Status::Complete(head_len)) => {
                let method = req.method.unwrap_or("").to_string();
                let url = req.path.unwrap_or("").to_string();
                let mut length: Option<u64> = None;
                for h in req.headers.iter() {
                    if h.name.eq_ignore_ascii_case("content-length") {
                        let v = std::str::from_utf8(h.value)
                            .ok()
                            .and_then(|v| v.trim().parse().ok());
                        length =
                            Some(v.ok_or((400, "Content-Length is not a number".to_string()))?);
                    } else if h.name.eq_ignore_ascii_case("transfer-encoding") {
                        return Err(Some((
                            411,
                            "send the body with a Content-Length (chunked bodies are not read)"
                                .into(),
                        )));
                    }
                }
                let length = length.unwrap_or(0);
                if length > MAX_BODY {
                    return Err(Some((
                        413,
                        format!("the request body is larger than {MAX_BODY} bytes"),
                    )));
                }
                let mut body = buf[head_len..].to_vec();
                let body = loop {
                    if body.len() as u64 >= length {
                        body.truncate(length as usize);
                        break Ok(body);
                    }
                    match read_some(stream, &mut chunk, deadline) {
                        Ok(k) => body.extend_from_slice(&chunk[..k]),
                        Err(()) => break Err("the request body did not arrive in time".to_string()),
                    }
                };
                return Ok(Request { method, url, body });
            }
            Ok(httparse::Status::Partial) if buf.len() <= MAX_HEAD => {}
            Ok(httparse::Status::Partial) => {
                return Err(Some((
                    431,
                    format!("the request head is larger than {MAX_HEAD} bytes"),
                )))
            }
            Err(e) => return Err(Some((400, format!("not an HTTP request: {e}")))),
        }
    }
}

fn answer(game: &Mutex<Game>, req: Request) -> (u16, Reply) {
    let (url, query) = match req.url.split_once('?') {
        Some((u, q)) => (u.to_string(), q.to_string()),
        None => (req.url.clone(), String::new()),
    };
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        route(game, &req.method, &url, &query, req.body)
    }))
    .unwrap_or_else(|_| {
        Err((
            500,
            "internal error: the request failed; the server keeps running".into(),
        ))
    });
    match outcome {
        Ok(r) => (200, r),
        Err((code, msg)) => (code, Reply::Json(json!({ "error": msg }))),
    }
}

fn reason(code: u16) -> &'static str {
    match code {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        411 => "Length Required",
        413 => "Payload Too Large",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "Error",
    }
}

fn write_response(stream: &mut TcpStream, code: u16, reply: &Reply) -> std::io::Result<()> {
    let (kind, body): (&str, Vec<u8>) = match reply {
        Reply::Page => ("text/html; charset=utf-8", PAGE.as_bytes().to_vec()),
        Reply::Json(v) => (
            "application/json",
            serde_json::to_vec(v).unwrap_or_default(),
        ),
    };
    let head = format!(
        "HTTP/1.1 {code} {}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\n\
         Connection: close\r\n\r\n",
        reason(code),
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(&body)?;
    stream.flush()
}

enum Reply {
    Page,
    Json(Value),
}

fn route(
    game: &Mutex<Game>,
    method: &str,
    url: &str,
    query: &str,
    body: Result<Vec<u8>, String>,
) -> Result<Reply, (u16, String)> {
    let lock = || game.lock().unwrap_or_else(|e| e.into_inner());
    match (method, url) {
        ("GET", "/" | "/index.html") => Ok(Reply::Page),
        ("GET", "/api/world") => {
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
        ("GET", "/api/state") => Ok(Reply::Json(lock().state())),
        ("POST", "/api/start" | "/api/step" | "/api/finish") => {
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
