//! Bounded load: at most a set number of calls of a service at work at once. A call beyond the
//! bound is refused at once — RESOURCE_EXHAUSTED naming the service and the bound, with gRPC's
//! retry pushback (`grpc-retry-pushback-ms`) — instead of queueing, so a burst costs a refusal
//! each, not memory. A call counts from its arrival until its response has been sent in full
//! (the end of a server stream), so a long capture stream holds its place while it streams.
//!
//! Health and reflection are never limited; a service without a bound (the orchestrator, which
//! admits sessions itself) neither.

use std::collections::HashMap;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tonic::body::Body;
use tonic::codegen::http;

/// The metadata key of gRPC's retry pushback: milliseconds a client should wait before it
/// tries again.
pub const RETRY_PUSHBACK_KEY: &str = "grpc-retry-pushback-ms";

/// Calls at work per stage service at most, by default: above what one orchestrator at its
/// defaults sends a stage (4 running sessions, 2 predictions in flight per worker), below what
/// fills a 2-core server's memory with 256 MiB streams.
pub const DEFAULT_MAX_CONCURRENT_CALLS: usize = 16;

/// How long a refused client is asked to wait, by default.
pub const DEFAULT_RETRY_AFTER: Duration = Duration::from_millis(500);

/// Calls at work per service at most: `glint.v1` service name → bound.
#[derive(Clone, Debug, Default)]
pub struct CallLimits {
    /// `(service name, bound)` pairs; a service not listed is not limited.
    pub per_service: Vec<(&'static str, usize)>,
    /// The retry pushback of a refusal.
    pub retry_after: Duration,
}

impl CallLimits {
    /// The same bound for each of `services` but those in `unbounded`.
    pub fn each(services: &[&'static str], bound: usize, unbounded: &[&str]) -> Self {
        Self {
            per_service: services
                .iter()
                .filter(|s| !unbounded.contains(s))
                .map(|s| (*s, bound))
                .collect(),
            retry_after: DEFAULT_RETRY_AFTER,
        }
    }
}

/// One service's bound and what it refused.
#[derive(Debug)]
struct Gate {
    permits: Arc<Semaphore>,
    bound: usize,
    refused: AtomicU64,
}

/// The tower layer that applies [`CallLimits`] ([`crate::serve`] adds it).
#[derive(Clone, Debug)]
pub struct CallLimitLayer {
    gates: Arc<HashMap<&'static str, Gate>>,
    retry_after: Duration,
}

impl CallLimitLayer {
    /// The layer enforcing `limits`: each listed service counts its own calls at work.
    pub fn new(limits: &CallLimits) -> Self {
        let gates = limits
            .per_service
            .iter()
            .map(|&(service, bound)| {
                let gate = Gate {
                    permits: Arc::new(Semaphore::new(bound)),
                    bound,
                    refused: AtomicU64::new(0),
                };
                (service, gate)
            })
            .collect();
        Self {
            gates: Arc::new(gates),
            retry_after: limits.retry_after,
        }
    }
}

impl<S> tower_layer::Layer<S> for CallLimitLayer {
    type Service = CallLimit<S>;

    fn layer(&self, inner: S) -> Self::Service {
        CallLimit {
            inner,
            gates: self.gates.clone(),
            retry_after: self.retry_after,
        }
    }
}

/// [`CallLimitLayer`]'s service.
#[derive(Clone, Debug)]
pub struct CallLimit<S> {
    inner: S,
    gates: Arc<HashMap<&'static str, Gate>>,
    retry_after: Duration,
}

/// The service of a gRPC path: `glint.v1.CameraService` of `/glint.v1.CameraService/Capture`.
fn service_of(path: &str) -> &str {
    path.trim_start_matches('/')
        .split_once('/')
        .map_or("", |(service, _)| service)
}

/// RESOURCE_EXHAUSTED for a call refused by `service`'s bound, with the retry pushback.
pub fn refusal(service: &str, bound: usize, retry_after: Duration) -> tonic::Status {
    let status = tonic::Status::resource_exhausted(format!(
        "{service}: {bound} calls at work already, its bound (--max-concurrent-calls); retry \
         in {} ms",
        retry_after.as_millis()
    ));
    with_retry_pushback(status, retry_after)
}

/// `status` carrying gRPC's retry pushback: the client should wait `after` before trying again.
pub fn with_retry_pushback(mut status: tonic::Status, after: Duration) -> tonic::Status {
    if let Ok(value) = after.as_millis().to_string().parse() {
        status.metadata_mut().insert(RETRY_PUSHBACK_KEY, value);
    }
    status
}

/// The retry pushback `status` carries, if any (whole milliseconds).
pub fn retry_pushback(status: &tonic::Status) -> Option<Duration> {
    let ms: u64 = status
        .metadata()
        .get(RETRY_PUSHBACK_KEY)?
        .to_str()
        .ok()?
        .parse()
        .ok()?;
    Some(Duration::from_millis(ms))
}

type BoxFuture<T> = Pin<Box<dyn std::future::Future<Output = T> + Send>>;

impl<S, B> tonic::codegen::Service<http::Request<B>> for CallLimit<S>
where
    S: tonic::codegen::Service<http::Request<B>, Response = http::Response<Body>>,
    S::Future: Send + 'static,
    S::Error: Send + 'static,
{
    type Response = http::Response<Body>;
    type Error = S::Error;
    type Future = BoxFuture<Result<Self::Response, Self::Error>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<B>) -> Self::Future {
        let service = service_of(request.uri().path());
        let Some((name, gate)) = self.gates.get_key_value(service) else {
            return Box::pin(self.inner.call(request));
        };
        let Ok(permit) = gate.permits.clone().try_acquire_owned() else {
            let refused = gate.refused.fetch_add(1, Ordering::Relaxed) + 1;
            tracing::debug!(
                "{name}: refused a call over its bound of {} ({refused} so far)",
                gate.bound
            );
            let status = refusal(name, gate.bound, self.retry_after);
            return Box::pin(std::future::ready(Ok(status.into_http())));
        };
        let response = self.inner.call(request);
        Box::pin(async move {
            let response = response.await?;
            // The place is held until the body (a whole server stream) has been sent.
            Ok(response.map(|body| Body::new(HeldBody { body, permit })))
        })
    }
}

/// A response body that holds its call's place until it ends or is dropped.
struct HeldBody {
    body: Body,
    #[allow(dead_code)] // held, never read: dropping it frees the place
    permit: OwnedSemaphorePermit,
}

impl http_body::Body for HeldBody {
    type Data = bytes::Bytes;
    type Error = tonic::Status;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
        Pin::new(&mut self.body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.body.size_hint()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_service_is_read_off_the_path() {
        assert_eq!(
            service_of("/glint.v1.CameraService/Capture"),
            "glint.v1.CameraService"
        );
        assert_eq!(
            service_of("/grpc.health.v1.Health/Check"),
            "grpc.health.v1.Health"
        );
        assert_eq!(service_of("/"), "");
        assert_eq!(service_of(""), "");
    }

    #[test]
    fn a_refusal_is_resource_exhausted_with_the_pushback() {
        let status = refusal("glint.v1.EstimationService", 3, Duration::from_millis(250));
        assert_eq!(status.code(), tonic::Code::ResourceExhausted);
        assert!(status.message().contains("glint.v1.EstimationService"));
        assert_eq!(retry_pushback(&status), Some(Duration::from_millis(250)));
        assert_eq!(
            retry_pushback(&tonic::Status::resource_exhausted("no hint")),
            None
        );
    }
}
