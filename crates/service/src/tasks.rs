//! A server's metrics registry, injected rather than installed process-wide, and the spawning
//! of tasks that keep it: every task the server spawns, every request it answers and every
//! blocking call it makes runs with the server's recorder set as the `metrics` crate's local
//! recorder, so the `metrics::counter!` and friends throughout the service record into it. Two servers in one process (tests) keep
//! separate metrics, and a process that installs no global recorder loses none.

use metrics_exporter_prometheus::{PrometheusBuilder, PrometheusHandle, PrometheusRecorder};
use std::cell::RefCell;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

/// Histogram buckets, in seconds: from half a millisecond (a kept path answer) to a minute (a
/// big build).
const BUCKETS: &[f64] = &[
    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
    60.0,
];

/// One server's metrics registry.
#[derive(Clone)]
pub struct Metrics {
    recorder: Arc<PrometheusRecorder>,
}

impl Metrics {
    /// A fresh, empty registry.
    pub fn new() -> Result<Metrics, String> {
        let recorder = PrometheusBuilder::new()
            .set_buckets(BUCKETS)
            .map_err(|e| format!("metrics recorder: {e}"))?
            .build_recorder();
        metrics::with_local_recorder(&recorder, crate::runtime::series::describe);
        Ok(Metrics {
            recorder: Arc::new(recorder),
        })
    }

    /// What `/metrics` renders.
    pub fn handle(&self) -> PrometheusHandle {
        self.recorder.handle()
    }

    /// `future`, recording into this registry whenever it runs.
    pub(crate) fn scope<F: Future>(&self, future: F) -> Recorded<F> {
        Recorded {
            recorder: Some(self.recorder.clone()),
            inner: Box::pin(future),
        }
    }
}

thread_local! {
    /// The registry of the future this thread is polling, for the tasks it spawns.
    static CURRENT: RefCell<Option<Arc<PrometheusRecorder>>> = const { RefCell::new(None) };
}

/// A future that records into its server's registry (none: whatever the process has).
pub(crate) struct Recorded<F: Future> {
    recorder: Option<Arc<PrometheusRecorder>>,
    inner: Pin<Box<F>>,
}

impl<F: Future> Future for Recorded<F> {
    type Output = F::Output;

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<F::Output> {
        let this = &mut *self;
        let Some(recorder) = this.recorder.clone() else {
            return this.inner.as_mut().poll(cx);
        };
        let previous = CURRENT.with(|c| c.replace(Some(recorder.clone())));
        let polled = metrics::with_local_recorder(&*recorder, || this.inner.as_mut().poll(cx));
        CURRENT.with(|c| *c.borrow_mut() = previous);
        polled
    }
}

/// `future`, recording into the registry of the future being polled now.
pub(crate) fn recorded<F: Future>(future: F) -> Recorded<F> {
    Recorded {
        recorder: CURRENT.with(|c| c.borrow().clone()),
        inner: Box::pin(future),
    }
}

/// `tokio::spawn`, the task recording into the spawning server's registry.
pub(crate) fn spawn<F>(future: F) -> tokio::task::JoinHandle<F::Output>
where
    F: Future + Send + 'static,
    F::Output: Send + 'static,
{
    tokio::spawn(recorded(future))
}

/// `work`, recording into the calling server's registry wherever it later runs (a blocking
/// thread, the query pool).
pub(crate) fn bind<F, R>(work: F) -> impl FnOnce() -> R + Send + 'static
where
    F: FnOnce() -> R + Send + 'static,
{
    let recorder = CURRENT.with(|c| c.borrow().clone());
    move || match recorder {
        Some(recorder) => metrics::with_local_recorder(&*recorder, work),
        None => work(),
    }
}

/// `tokio::task::spawn_blocking`, the work recording into the calling server's registry.
pub(crate) fn spawn_blocking<F, R>(work: F) -> tokio::task::JoinHandle<R>
where
    F: FnOnce() -> R + Send + 'static,
    R: Send + 'static,
{
    tokio::task::spawn_blocking(bind(work))
}
