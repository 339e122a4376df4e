//! The stages over gRPC: each implements its [`crate::stages`] trait by calling a stage's
//! server, so [`crate::session::run`] drives a deployment exactly as it drives the libraries.
//!
//! The traits are synchronous (a session runs on a blocking thread); these implementations
//! hold a tokio runtime [`Handle`] and block on their calls. Never call them from inside an
//! async task: run the session with `tokio::task::spawn_blocking` (or on a plain thread).

pub mod camera;

use std::future::Future;
use std::time::Duration;

use tokio::runtime::Handle;
use tonic::Code;

use crate::stages::StageError;
pub use glint_server::security::{AuthChannel, ClientSecurity};

pub mod estimation;
pub mod prediction;

/// A stage's server address, how long its calls may take, and how they are secured.
#[derive(Clone, Debug)]
pub struct Endpoint {
    /// `http://host:port` (a bare `host:port` gets `http://`, or `https://` with TLS).
    pub uri: String,
    /// Deadline of every call, sent as `grpc-timeout` so the server stops working on it too.
    pub deadline: Duration,
    /// The token sent and the TLS settings (default: neither).
    pub security: ClientSecurity,
}

impl Endpoint {
    /// The server at `uri`, every call due within `deadline`, with neither token nor TLS.
    pub fn new(uri: &str, deadline: Duration) -> Self {
        Self::secured(uri, deadline, ClientSecurity::default())
    }

    /// The server at `uri` called with `security`'s token and TLS; a bare `host:port` gets
    /// `https://` with TLS, else `http://`.
    pub fn secured(uri: &str, deadline: Duration, security: ClientSecurity) -> Self {
        Self {
            uri: security.uri(uri),
            deadline,
            security,
        }
    }

    /// A lazily connecting channel: the first call connects, a dropped connection reconnects.
    pub fn channel(&self) -> Result<AuthChannel, StageError> {
        let invalid = |e: glint_server::ServerError| StageError::invalid("endpoint", e.to_string());
        let channel = self
            .security
            .endpoint(&self.uri)
            .map_err(invalid)?
            .connect_timeout(self.deadline.min(Duration::from_secs(5)))
            .tcp_nodelay(true)
            .connect_lazy();
        self.security.authorize(channel).map_err(invalid)
    }
}

/// Blocks the calling (non-async) thread on `future` with `handle`'s runtime.
pub fn block_on<F: Future>(handle: &Handle, future: F) -> F::Output {
    handle.block_on(future)
}

/// A request with `deadline` set (propagated to the server as `grpc-timeout`).
pub fn request<T>(message: T, deadline: Duration) -> tonic::Request<T> {
    let mut request = tonic::Request::new(message);
    request.set_timeout(deadline);
    request
}

/// `call`, made again after the stage's retry hint for as long as the stage answers that it is
/// overloaded (RESOURCE_EXHAUSTED: a stage server at its `--max-concurrent-calls`), for at most
/// `patience` in all; then its last answer. A session waits its turn at a busy stage instead of
/// failing.
pub fn when_admitted<T>(
    patience: Duration,
    mut call: impl FnMut() -> Result<T, StageError>,
) -> Result<T, StageError> {
    let started = std::time::Instant::now();
    loop {
        match call() {
            Err(StageError::Overloaded { retry_after_ms, .. }) if started.elapsed() < patience => {
                tracing::debug!("a stage is overloaded: calling again in {retry_after_ms} ms");
                std::thread::sleep(Duration::from_millis(retry_after_ms.clamp(10, 10_000)));
            }
            result => return result,
        }
    }
}

pub use glint_server::load::RETRY_PUSHBACK_KEY;
use glint_server::load::{retry_pushback, with_retry_pushback};

/// The wait after a RESOURCE_EXHAUSTED that names none, ms.
const DEFAULT_RETRY_AFTER_MS: u64 = 500;

/// What a failed call means to a session. INVALID_ARGUMENT messages start with the field
/// (`field: message`, as every Glint server writes them); RESOURCE_EXHAUSTED is
/// [`StageError::Overloaded`] with the status's retry pushback (500 ms without one);
/// DEADLINE_EXCEEDED and ABORTED are [`StageError::Unavailable`], like UNAVAILABLE.
pub fn stage_error(status: &tonic::Status) -> StageError {
    let message = status.message().to_owned();
    match status.code() {
        Code::InvalidArgument => match message.split_once(": ") {
            Some((field, rest)) if !field.contains(' ') => StageError::invalid(field, rest),
            _ => StageError::invalid("request", message),
        },
        Code::NotFound => StageError::NotFound(message),
        Code::FailedPrecondition | Code::OutOfRange => StageError::FailedPrecondition(message),
        // A stage at its bound of calls: wait its retry hint and try again.
        Code::ResourceExhausted => StageError::Overloaded {
            message,
            retry_after_ms: retry_pushback(status)
                .map_or(DEFAULT_RETRY_AFTER_MS, |d| d.as_millis() as u64),
        },
        Code::Unavailable | Code::DeadlineExceeded | Code::Aborted => {
            StageError::Unavailable(format!("{}: {message}", status.code()))
        }
        Code::Cancelled => StageError::Cancelled,
        Code::DataLoss => StageError::DataLoss(message),
        _ => StageError::Internal(format!("{}: {message}", status.code())),
    }
}

/// The status a server answers for a stage's error (the inverse of [`stage_error`]).
pub fn status_of(error: &StageError) -> tonic::Status {
    match error {
        StageError::InvalidArgument { .. } => tonic::Status::invalid_argument(error.to_string()),
        StageError::NotFound(m) => tonic::Status::not_found(m.clone()),
        StageError::FailedPrecondition(m) => tonic::Status::failed_precondition(m.clone()),
        StageError::Unavailable(m) => tonic::Status::unavailable(m.clone()),
        StageError::Cancelled => tonic::Status::cancelled("cancelled"),
        StageError::Overloaded { retry_after_ms, .. } => with_retry_pushback(
            tonic::Status::resource_exhausted(error.to_string()),
            Duration::from_millis(*retry_after_ms),
        ),
        StageError::DataLoss(m) => tonic::Status::data_loss(m.clone()),
        StageError::Internal(m) => tonic::Status::internal(m.clone()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn overloaded() -> StageError {
        StageError::Overloaded {
            message: "at its bound".into(),
            retry_after_ms: 1,
        }
    }

    #[test]
    fn an_overloaded_stage_is_called_again_until_it_admits_the_call() {
        let mut calls = 0;
        let answer = when_admitted(Duration::from_secs(10), || {
            calls += 1;
            if calls < 3 {
                Err(overloaded())
            } else {
                Ok(calls)
            }
        });
        assert_eq!(answer.unwrap(), 3);
        // Other errors are not retried ...
        let mut calls = 0;
        let answer: Result<(), _> = when_admitted(Duration::from_secs(10), || {
            calls += 1;
            Err(StageError::Unavailable("down".into()))
        });
        assert!(matches!(answer, Err(StageError::Unavailable(_))));
        assert_eq!(calls, 1);
        // ... and patience ends: the last answer is the caller's.
        let answer: Result<(), _> = when_admitted(Duration::from_millis(50), || Err(overloaded()));
        assert!(matches!(answer, Err(StageError::Overloaded { .. })));
    }

    #[test]
    fn statuses_round_trip_through_stage_errors() {
        let errors = [
            StageError::invalid("t_w_c.rotation", "norm is 2, not 1"),
            StageError::NotFound("object abc".into()),
            StageError::FailedPrecondition("too few points".into()),
            StageError::Cancelled,
            StageError::DataLoss("blob ab… is damaged".into()),
        ];
        for e in errors {
            assert_eq!(stage_error(&status_of(&e)), e);
        }
        assert!(matches!(
            stage_error(&tonic::Status::deadline_exceeded("slow")),
            StageError::Unavailable(_)
        ));
        // Overloaded: RESOURCE_EXHAUSTED with gRPC's retry pushback.
        let status = status_of(&StageError::Overloaded {
            message: "busy".into(),
            retry_after_ms: 1000,
        });
        assert_eq!(status.code(), Code::ResourceExhausted);
        assert_eq!(retry_pushback(&status), Some(Duration::from_millis(1000)));
        // ... and back: an overloaded stage, with its retry hint.
        assert!(matches!(
            stage_error(&status),
            StageError::Overloaded {
                retry_after_ms: 1000,
                ..
            }
        ));
        assert!(matches!(
            stage_error(&tonic::Status::resource_exhausted("no hint")),
            StageError::Overloaded {
                retry_after_ms: DEFAULT_RETRY_AFTER_MS,
                ..
            }
        ));
    }
}
