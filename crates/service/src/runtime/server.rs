//! The listener: accepts connections up to a cap, serves each with hyper (HTTP/1.1, and h2c
//! for clients that ask), closes connections that stall or idle, and drains them on shutdown.
//!
//! axum's own `serve` sets none of these limits, so the accept loop is ours; hyper and
//! hyper-util do the protocol work. What guards a connection here (the body and whole-request
//! timeouts are layers of the app, `crate::http::app`):
//! - **headers**: hyper's `header_read_timeout`, counted from the first byte a request is
//!   awaited, so a slow-loris client dribbling a header is cut off;
//! - **idle**: a watchdog closes a connection with no request in flight and no answer going
//!   out for `idle`; bytes alone (HTTP/2 PINGs, stray data) do not keep it open;
//! - **stalled answers**: the watchdog closes a connection whose answers made no progress for
//!   `write_timeout` (the client stopped reading), which frees them (`http::delivery`); so does
//!   a connection asked to close that has not closed within `write_timeout`;
//! - **connections**: at most `max_connections` served at once, and `per_client` from one
//!   address; the accept loop waits for one to close before taking the next, so excess clients
//!   queue in the kernel's backlog rather than in our memory;
//! - **HTTP/2 streams**: at most `max_streams` open on one connection.

use crate::http::delivery::{Connection, Phase};
use axum::Router;
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::conn::auto;
use hyper_util::service::TowerToHyperService;
use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Semaphore, watch};
use tower::ServiceExt;

/// How connections are limited (the flags of the same names, `config::ServeArgs`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ConnectionLimits {
    pub max_connections: usize,
    pub header_timeout: Duration,
    pub idle_timeout: Duration,
    pub write_timeout: Duration,
    /// Connections from one address; 0: no limit.
    pub per_client: usize,
    pub max_streams: u32,
}

/// The open connections of a server whose accept loop has stopped.
pub(crate) struct OpenConnections {
    permits: Arc<Semaphore>,
    max: usize,
    closing: watch::Sender<bool>,
}

impl OpenConnections {
    /// How many connections are still open.
    pub fn count(&self) -> usize {
        self.max - self.permits.available_permits()
    }

    /// Asks every connection to close once its request in flight is answered, and waits until
    /// they are closed or `deadline` passes; returns how many were still open then.
    pub async fn drain(&self, deadline: Instant) -> usize {
        let _ = self.closing.send(true);
        let all = u32::try_from(self.max).unwrap_or(u32::MAX);
        let _ = tokio::time::timeout_at(deadline.into(), self.permits.acquire_many(all)).await;
        self.count()
    }
}

/// Serves `app` on `listener` until `stop` resolves, then returns the connections still open.
pub(crate) async fn serve(
    listener: TcpListener,
    app: Router,
    limits: ConnectionLimits,
    stop: impl Future<Output = ()>,
) -> OpenConnections {
    let max = limits.max_connections.clamp(1, Semaphore::MAX_PERMITS);
    let permits = Arc::new(Semaphore::new(max));
    let (closing, _) = watch::channel(false);
    let mut builder = auto::Builder::new(TokioExecutor::new());
    builder
        .http1()
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout);
    builder
        .http2()
        .timer(TokioTimer::new())
        .max_concurrent_streams(limits.max_streams);
    let builder = Arc::new(builder);
    let clients = Arc::new(Clients::default());
    tokio::pin!(stop);
    loop {
        let permit = tokio::select! {
            _ = &mut stop => break,
            permit = permits.clone().acquire_owned() => permit.expect("never closed"),
        };
        let (stream, peer) = tokio::select! {
            _ = &mut stop => break,
            accepted = listener.accept() => match accepted {
                Ok(accepted) => accepted,
                Err(e) => {
                    // EMFILE and the like: back off instead of spinning on the error.
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
        };
        let Some(client) = clients.admit(peer.ip(), limits.per_client) else {
            metrics::counter!("irs_connections_refused_per_client_total").increment(1);
            tracing::debug!(%peer, limit = limits.per_client, "connection refused: the client holds its limit");
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        metrics::counter!("irs_connections_total").increment(1);
        let (builder, app, closing) = (builder.clone(), app.clone(), closing.subscribe());
        crate::tasks::spawn(async move {
            connection(&builder, stream, app, &limits, closing).await;
            tracing::debug!(%peer, "connection closed");
            drop(client);
            drop(permit);
        });
    }
    OpenConnections {
        permits,
        max,
        closing,
    }
}

/// How long a connection asked to close with nothing in flight may take to close by itself.
const IDLE_GRACE: Duration = Duration::from_secs(1);

/// Serves one connection until it ends, closing it when it idles, its answers stall or the
/// server drains.
async fn connection(
    builder: &auto::Builder<TokioExecutor>,
    stream: TcpStream,
    app: Router,
    limits: &ConnectionLimits,
    mut closing: watch::Receiver<bool>,
) {
    let watched = Arc::new(Connection::new());
    let io = TokioIo::new(stream);
    let counted = watched.clone();
    let service = tower::service_fn(move |mut request: axum::extract::Request<_>| {
        let in_flight = counted.request();
        request.extensions_mut().insert(counted.clone());
        let answer = app.clone().oneshot(request);
        // Recorded: an HTTP/2 stream's future runs in a task hyper spawns, not in this one.
        crate::tasks::recorded(async move {
            let response = answer.await;
            drop(in_flight);
            response
        })
    });
    let conn = builder.serve_connection_with_upgrades(io, TowerToHyperService::new(service));
    tokio::pin!(conn);
    // Check often enough that a connection outlives its timeouts by at most a quarter.
    let tick = (limits.idle_timeout.min(limits.write_timeout) / 4).max(Duration::from_millis(100));
    // Once asked to close gracefully, the connection has `write_timeout` to finish what it
    // is answering; one closed for idling has nothing to finish, so a client that does not
    // complete HTTP/2's closing handshake (it never acknowledges our PING) gets IDLE_GRACE.
    let mut closing_since: Option<Instant> = None;
    loop {
        tokio::select! {
            _ = conn.as_mut() => return,
            changed = closing.changed(), if closing_since.is_none() => {
                if changed.is_err() || *closing.borrow() {
                    closing_since = Some(Instant::now());
                    conn.as_mut().graceful_shutdown();
                }
            }
            _ = tokio::time::sleep(tick) => {
                match watched.state() {
                    Phase::Sending(still) if still >= limits.write_timeout => {
                        metrics::counter!("irs_connections_stalled_closed_total").increment(1);
                        tracing::info!(stalled_s = still.as_secs_f64(), "connection closed: its answers made no progress");
                        return;
                    }
                    Phase::Idle(idle) if idle >= limits.idle_timeout && closing_since.is_none() => {
                        closing_since = Some(Instant::now());
                        metrics::counter!("irs_connections_idle_closed_total").increment(1);
                        conn.as_mut().graceful_shutdown();
                    }
                    _ => {}
                }
                if let Some(since) = closing_since {
                    let waited = since.elapsed();
                    let still_idle = matches!(watched.state(), Phase::Idle(_));
                    if waited >= limits.write_timeout || (still_idle && waited >= IDLE_GRACE) {
                        return;
                    }
                }
            }
        }
    }
}

/// Connections per client address, for `per_client`.
#[derive(Default)]
struct Clients {
    open: Mutex<HashMap<IpAddr, usize>>,
}

impl Clients {
    /// A slot for one more connection from `ip`, or `None` when it holds `limit` (0: no limit).
    fn admit(self: &Arc<Self>, ip: IpAddr, limit: usize) -> Option<ClientSlot> {
        let mut open = self.open.lock().unwrap_or_else(|e| e.into_inner());
        let count = open.entry(ip).or_insert(0);
        if limit > 0 && *count >= limit {
            return None;
        }
        *count += 1;
        Some(ClientSlot {
            clients: self.clone(),
            ip,
        })
    }
}

/// One connection's place in [`Clients`], given back when it closes.
struct ClientSlot {
    clients: Arc<Clients>,
    ip: IpAddr,
}

impl Drop for ClientSlot {
    fn drop(&mut self) {
        let mut open = self.clients.open.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(count) = open.get_mut(&self.ip) {
            *count -= 1;
            if *count == 0 {
                open.remove(&self.ip);
            }
        }
    }
}
