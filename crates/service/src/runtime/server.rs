//! The listener: accepts connections up to a cap, serves each with hyper (HTTP/1.1, and h2c
//! for clients that ask), closes connections that stall or idle, and drains them on shutdown.
//!
//! axum's own `serve` sets none of these limits, so the accept loop is ours; hyper and
//! hyper-util do the protocol work. Three timeouts guard a connection here (the body and
//! whole-request timeouts are layers of the app, `crate::http::app`):
//! - **headers**: hyper's `header_read_timeout`, counted from the first byte a request is
//!   awaited, so a slow-loris client dribbling a header is cut off;
//! - **idle keep-alive**: a watchdog closes a connection with no request in flight and no
//!   bytes either way for `idle` (hyper has no such timeout of its own);
//! - **connections**: at most `max_connections` served at once; the accept loop waits for one
//!   to close before taking the next, so excess clients queue in the kernel's backlog rather
//!   than in our memory.

use axum::Router;
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::conn::auto;
use hyper_util::service::TowerToHyperService;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Semaphore, watch};
use tower::ServiceExt;

/// How connections are limited.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ConnectionLimits {
    pub max_connections: usize,
    pub header_timeout: Duration,
    pub idle_timeout: Duration,
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
    let builder = Arc::new(builder);
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
        let _ = stream.set_nodelay(true);
        metrics::counter!("irs_connections_total").increment(1);
        let (builder, app, closing) = (builder.clone(), app.clone(), closing.subscribe());
        crate::tasks::spawn(async move {
            connection(&builder, stream, app, limits.idle_timeout, closing).await;
            tracing::debug!(%peer, "connection closed");
            drop(permit);
        });
    }
    OpenConnections {
        permits,
        max,
        closing,
    }
}

/// Serves one connection until it ends, closing it when it idles or the server drains.
async fn connection(
    builder: &auto::Builder<TokioExecutor>,
    stream: TcpStream,
    app: Router,
    idle: Duration,
    mut closing: watch::Receiver<bool>,
) {
    let activity = Arc::new(Activity::new());
    let io = TokioIo::new(Tracked {
        inner: stream,
        activity: activity.clone(),
    });
    let counted = activity.clone();
    let service = tower::service_fn(move |request| {
        let in_flight = InFlight::new(counted.clone());
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
    // Check often enough that a connection outlives its idle timeout by at most a quarter.
    let tick = (idle / 4).max(Duration::from_millis(100));
    let mut closing_asked = false;
    loop {
        tokio::select! {
            _ = conn.as_mut() => return,
            changed = closing.changed(), if !closing_asked => {
                if changed.is_err() || *closing.borrow() {
                    closing_asked = true;
                    conn.as_mut().graceful_shutdown();
                }
            }
            _ = tokio::time::sleep(tick), if !closing_asked => {
                if activity.requests.load(Ordering::Relaxed) == 0 && activity.idle_for() >= idle {
                    closing_asked = true;
                    metrics::counter!("irs_connections_idle_closed_total").increment(1);
                    conn.as_mut().graceful_shutdown();
                }
            }
        }
    }
}

/// When a connection last moved bytes, and how many of its requests are being answered.
struct Activity {
    epoch: Instant,
    last_ms: AtomicU64,
    requests: AtomicUsize,
}

impl Activity {
    fn new() -> Self {
        Activity {
            epoch: Instant::now(),
            last_ms: AtomicU64::new(0),
            requests: AtomicUsize::new(0),
        }
    }
    fn touch(&self) {
        let now = self.epoch.elapsed().as_millis() as u64;
        self.last_ms.store(now, Ordering::Relaxed);
    }
    fn idle_for(&self) -> Duration {
        let last = Duration::from_millis(self.last_ms.load(Ordering::Relaxed));
        self.epoch.elapsed().saturating_sub(last)
    }
}

/// Counts a request in flight for as long as it lives.
struct InFlight(Arc<Activity>);

impl InFlight {
    fn new(activity: Arc<Activity>) -> Self {
        activity.requests.fetch_add(1, Ordering::Relaxed);
        InFlight(activity)
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        self.0.requests.fetch_sub(1, Ordering::Relaxed);
        self.0.touch();
    }
}

/// A TCP stream that records when bytes last moved.
struct Tracked {
    inner: TcpStream,
    activity: Arc<Activity>,
}

impl AsyncRead for Tracked {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let polled = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(polled, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.activity.touch();
        }
        polled
    }
}

impl AsyncWrite for Tracked {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let polled = Pin::new(&mut self.inner).poll_write(cx, buf);
        if matches!(polled, Poll::Ready(Ok(n)) if n > 0) {
            self.activity.touch();
        }
        polled
    }
    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let polled = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        if matches!(polled, Poll::Ready(Ok(n)) if n > 0) {
            self.activity.touch();
        }
        polled
    }
    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }
    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
