//! `--view PORT`: the same channels as the MCAP recording, served live over the Foxglove WebSocket protocol
//! (subprotocol `foxglove.websocket.v1`: `serverInfo` and `advertise` on connect, `subscribe`/`unsubscribe` from the
//! client, binary message-data frames), so Foxglove's "Open connection" shows a running tracker.
//!
//! The frame loop only calls [`LiveView::publish`]: it hands the encoded frame to each client's queue of
//! [`QUEUE_FRAMES`] without waiting (a full queue drops the frame for that client and counts it), so a slow or stuck
//! viewer never stalls tracking. An accept thread and one thread per client (at most [`MAX_CLIENTS`]) do all socket
//! I/O with blocking sockets and timeouts. Per frame in the loop: one `Arc` and a lock held for a few `try_send`s.

use std::io;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tungstenite::{Message as WsMessage, WebSocket};

use super::{FrameMessages, Topic, schemas};

/// The WebSocket subprotocol of the Foxglove protocol version spoken here.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// Frames queued per client before new ones are dropped for it.
pub const QUEUE_FRAMES: usize = 2;
/// Viewers served at once; more are refused at the handshake.
pub const MAX_CLIENTS: usize = 8;

/// Counters of the live view (for the end-of-run summary and logs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LiveStats {
    /// Clients connected now.
    pub clients: usize,
    /// Clients that connected since start.
    pub connections: u64,
    /// Frames handed to client queues.
    pub queued: u64,
    /// Frames dropped because a client's queue was full.
    pub dropped: u64,
}

struct Shared {
    stop: AtomicBool,
    queues: Mutex<Vec<SyncSender<Arc<FrameMessages>>>>,
    clients: AtomicUsize,
    subscribed: AtomicUsize,
    connections: AtomicU64,
    queued: AtomicU64,
    dropped: AtomicU64,
}

impl Shared {
    fn queues(&self) -> MutexGuard<'_, Vec<SyncSender<Arc<FrameMessages>>>> {
        // A panicked client thread cannot leave the list half-updated (push/retain only): keep serving.
        self.queues
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// A running live-view server.
pub struct LiveView {
    addr: SocketAddr,
    shared: Arc<Shared>,
    accept: Option<JoinHandle<()>>,
}

/// `PORT` (all interfaces) or `HOST:PORT`, as `--view` takes it.
pub fn parse_addr(s: &str) -> Result<SocketAddr, String> {
    if let Ok(port) = s.parse::<u16>() {
        return Ok(SocketAddr::from(([0, 0, 0, 0], port)));
    }
    s.parse::<SocketAddr>()
        .map_err(|_| format!("{s:?} is neither a port (e.g. 8765) nor HOST:PORT (e.g. 127.0.0.1:8765)"))
}

impl LiveView {
    /// Listen on `addr` (port 0 picks a free one: see [`LiveView::local_addr`]).
    pub fn bind(addr: SocketAddr) -> io::Result<Self> {
        let listener = TcpListener::bind(addr)?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let shared = Arc::new(Shared {
            stop: AtomicBool::new(false),
            queues: Mutex::new(Vec::new()),
            clients: AtomicUsize::new(0),
            subscribed: AtomicUsize::new(0),
            connections: AtomicU64::new(0),
            queued: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
        });
        let for_thread = Arc::clone(&shared);
        let accept = std::thread::Builder::new()
            .name("live-view-accept".into())
            .spawn(move || accept_loop(listener, for_thread))?;
        tracing::info!("live view: Foxglove WebSocket server on ws://{addr}");
        Ok(LiveView {
            addr,
            shared,
            accept: Some(accept),
        })
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Hand one frame to every connected client without blocking; full queues drop it (counted).
    pub fn publish(&self, frame: FrameMessages) {
        let frame = Arc::new(frame);
        let mut queues = self.shared.queues();
        queues.retain(|q| match q.try_send(Arc::clone(&frame)) {
            Ok(()) => {
                self.shared.queued.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(TrySendError::Full(_)) => {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(TrySendError::Disconnected(_)) => false,
        });
    }

    /// Whether any client is subscribed to at least one channel (nothing published reaches anyone otherwise).
    pub fn has_subscribers(&self) -> bool {
        self.shared.subscribed.load(Ordering::Relaxed) > 0
    }

    /// Wait up to `timeout` for a subscribed client (replay's `--view-wait`); true when one is there.
    pub fn wait_for_subscriber(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        while !self.has_subscribers() {
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        true
    }

    /// The counters so far.
    pub fn stats(&self) -> LiveStats {
        LiveStats {
            clients: self.shared.clients.load(Ordering::Relaxed),
            connections: self.shared.connections.load(Ordering::Relaxed),
            queued: self.shared.queued.load(Ordering::Relaxed),
            dropped: self.shared.dropped.load(Ordering::Relaxed),
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        // Closing the queues ends the client threads after they drain what they hold.
        self.shared.queues().clear();
        if let Some(t) = self.accept.take() {
            let _ = t.join();
        }
    }
}

fn accept_loop(listener: TcpListener, shared: Arc<Shared>) {
    while !shared.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, peer)) => {
                let shared = Arc::clone(&shared);
                let spawned = std::thread::Builder::new()
                    .name("live-view-client".into())
                    .spawn(move || {
                        if let Err(e) = serve(stream, &shared) {
                            tracing::info!("live view: client {peer}: {e}");
                        }
                    });
                if let Err(e) = spawned {
                    tracing::warn!("live view: cannot start a client thread: {e}");
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => std::thread::sleep(Duration::from_millis(25)),
            Err(e) => {
                tracing::warn!("live view: accept: {e}");
                std::thread::sleep(Duration::from_millis(200));
            }
        }
    }
}

/// Decrements the client count when a client thread ends, however it ends.
struct ClientGuard<'a> {
    shared: &'a Shared,
    subscribed: bool,
}

impl Drop for ClientGuard<'_> {
    fn drop(&mut self) {
        self.shared.clients.fetch_sub(1, Ordering::Relaxed);
        if self.subscribed {
            self.shared.subscribed.fetch_sub(1, Ordering::Relaxed);
        }
    }
}

type Error = Box<dyn std::error::Error + Send + Sync>;

fn serve(stream: TcpStream, shared: &Shared) -> Result<(), Error> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
    stream.set_write_timeout(Some(Duration::from_secs(5)))?;
    let full = shared.clients.fetch_add(1, Ordering::Relaxed) >= MAX_CLIENTS;
    let mut guard = ClientGuard {
        shared,
        subscribed: false,
    };
    // The callback's signature is tungstenite's (its error type is large, not ours to box).
    #[allow(clippy::result_large_err)]
    let callback = |req: &Request, mut resp: Response| -> Result<Response, ErrorResponse> {
        let offered = req
            .headers()
            .get_all("Sec-WebSocket-Protocol")
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(','))
            .any(|p| p.trim() == SUBPROTOCOL);
        let refuse = |code: u16, why: &str| {
            let mut r = ErrorResponse::new(Some(why.to_owned()));
            *r.status_mut() = tungstenite::http::StatusCode::from_u16(code).unwrap_or_default();
            r
        };
        if full {
            return Err(refuse(503, "too many live-view clients"));
        }
        if !offered {
            return Err(refuse(
                400,
                "the client must offer the foxglove.websocket.v1 subprotocol",
            ));
        }
        resp.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            tungstenite::http::HeaderValue::from_static(SUBPROTOCOL),
        );
        Ok(resp)
    };
    let mut ws = tungstenite::accept_hdr(stream, callback).map_err(|e| format!("handshake: {e}"))?;
    shared.connections.fetch_add(1, Ordering::Relaxed);
    ws.send(WsMessage::text(server_info().to_string()))?;
    ws.send(WsMessage::text(advertise().to_string()))?;
    let (tx, rx) = sync_channel(QUEUE_FRAMES);
    shared.queues().push(tx);
    ws.get_mut().set_read_timeout(Some(Duration::from_millis(5)))?;
    // channel id → subscription id
    let mut subscriptions: Vec<(u16, u32)> = Vec::new();
    loop {
        match ws.read() {
            Ok(WsMessage::Text(text)) => {
                handle_client_op(&text, &mut subscriptions, &mut ws)?;
                let any = !subscriptions.is_empty();
                if any != guard.subscribed {
                    if any {
                        shared.subscribed.fetch_add(1, Ordering::Relaxed);
                    } else {
                        shared.subscribed.fetch_sub(1, Ordering::Relaxed);
                    }
                    guard.subscribed = any;
                }
                continue;
            }
            Ok(WsMessage::Close(_)) => return Ok(()),
            Ok(_) => continue,
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {}
            Err(tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed) => return Ok(()),
            Err(e) => return Err(e.into()),
        }
        match next_frame(&rx) {
            Next::Frame(frame) => send_frame(&mut ws, &frame, &subscriptions)?,
            Next::Idle => {}
            Next::Closed => {
                let _ = ws.close(None);
                let _ = ws.flush();
                return Ok(());
            }
        }
    }
}

enum Next {
    Frame(Arc<FrameMessages>),
    Idle,
    Closed,
}

fn next_frame(rx: &Receiver<Arc<FrameMessages>>) -> Next {
    match rx.recv_timeout(Duration::from_millis(20)) {
        Ok(f) => Next::Frame(f),
        Err(RecvTimeoutError::Timeout) => Next::Idle,
        Err(RecvTimeoutError::Disconnected) => Next::Closed,
    }
}

fn send_frame(
    ws: &mut WebSocket<TcpStream>,
    frame: &FrameMessages,
    subscriptions: &[(u16, u32)],
) -> Result<(), Error> {
    for (topic, data) in &frame.items {
        let Some(&(_, sub)) = subscriptions.iter().find(|(c, _)| *c == topic.id()) else {
            continue;
        };
        // Message Data: opcode 1, subscription id (u32 LE), log time in ns (u64 LE), payload.
        let mut buf = Vec::with_capacity(13 + data.len());
        buf.push(1);
        buf.extend_from_slice(&sub.to_le_bytes());
        buf.extend_from_slice(&frame.log_ns.to_le_bytes());
        buf.extend_from_slice(data);
        ws.send(WsMessage::binary(buf))?;
    }
    Ok(())
}

/// `subscribe` / `unsubscribe`; anything else is answered with a warning status and ignored.
fn handle_client_op(
    text: &str,
    subscriptions: &mut Vec<(u16, u32)>,
    ws: &mut WebSocket<TcpStream>,
) -> Result<(), Error> {
    let v: Value = match serde_json::from_str(text) {
        Ok(v) => v,
        Err(e) => return status(ws, 1, &format!("not JSON: {e}")),
    };
    match v.get("op").and_then(Value::as_str) {
        Some("subscribe") => {
            for s in v
                .get("subscriptions")
                .and_then(Value::as_array)
                .into_iter()
                .flatten()
            {
                let id = s
                    .get("id")
                    .and_then(Value::as_u64)
                    .and_then(|i| u32::try_from(i).ok());
                let channel = s
                    .get("channelId")
                    .and_then(Value::as_u64)
                    .and_then(|c| u16::try_from(c).ok());
                match (id, channel) {
                    (Some(id), Some(ch)) if Topic::ALL.iter().any(|t| t.id() == ch) => {
                        if subscriptions.iter().any(|(_, s)| *s == id) {
                            status(ws, 1, &format!("subscription id {id} is in use"))?;
                        } else {
                            subscriptions.retain(|(c, _)| *c != ch);
                            subscriptions.push((ch, id));
                        }
                    }
                    _ => status(ws, 1, &format!("bad subscription {s}"))?,
                }
            }
            Ok(())
        }
        Some("unsubscribe") => {
            let ids: Vec<u64> = v
                .get("subscriptionIds")
                .and_then(Value::as_array)
                .into_iter()
                .flatten()
                .filter_map(Value::as_u64)
                .collect();
            subscriptions.retain(|(_, s)| !ids.contains(&(*s as u64)));
            Ok(())
        }
        Some(op) => status(
            ws,
            1,
            &format!("operation {op:?} is not supported by this server"),
        ),
        None => status(ws, 1, "message without an `op`"),
    }
}

fn status(ws: &mut WebSocket<TcpStream>, level: u8, message: &str) -> Result<(), Error> {
    ws.send(WsMessage::text(
        json!({ "op": "status", "level": level, "message": message }).to_string(),
    ))?;
    Ok(())
}

fn server_info() -> Value {
    json!({
        "op": "serverInfo",
        "name": concat!("supine ", env!("CARGO_PKG_VERSION")),
        "capabilities": [],
        "metadata": {},
        "sessionId": format!("{}", std::process::id()),
    })
}

fn advertise() -> Value {
    let channels: Vec<Value> = Topic::ALL
        .iter()
        .map(|t| {
            json!({
                "id": t.id(),
                "topic": t.name(),
                "encoding": "json",
                "schemaName": t.schema_name(),
                "schema": schemas::schema_text(*t),
                "schemaEncoding": "jsonschema",
            })
        })
        .collect();
    json!({ "op": "advertise", "channels": channels })
}
