//! What every Glint gRPC server shares, so that a stage's server (`src/server.rs` behind its
//! crate's `server` feature) is only its handlers:
//!
//! - [`serve`]: listens on a bound TCP listener with the stage's services plus
//!   `grpc.health.v1.Health` and server reflection (v1) over every `glint.v1` file; reports
//!   the stage's services SERVING while up and NOT_SERVING as soon as shutdown begins, then
//!   drains connections within [`ServeConfig::drain_timeout`];
//! - [`healthcheck`]: the client behind `glint healthcheck` (and container probes);
//! - [`process::ServerProcess`]: a server as a child process (benchmarks, tests);
//! - [`load`]: at most N calls of a service at work; beyond, RESOURCE_EXHAUSTED at once;
//! - [`blocking`]: runs a synchronous library call on tokio's blocking pool, turning a panic
//!   into INTERNAL instead of a dead worker.
//!
//! Nothing here knows a stage's domain; nothing in a stage's library knows this crate.

#![cfg_attr(not(test), deny(clippy::expect_used, clippy::unwrap_used))]
#![warn(missing_docs)]

pub mod load;
pub mod process;
pub mod security;

use std::future::Future;
use std::net::SocketAddr;
use std::time::Duration;

use tokio::net::TcpListener;
use tokio_stream::wrappers::TcpListenerStream;
use tonic::service::Routes;
use tonic_health::ServingStatus;
use tonic_health::pb::HealthCheckRequest;
pub use tonic_health::pb::health_check_response::ServingStatus as HealthStatus;
use tonic_health::pb::health_client::HealthClient;

/// Why a server could not run or a health check failed.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// The listen address cannot be bound: it is in use, not an address of this host, or a
    /// port that needs privileges; give another `--listen`.
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// The address as given (HOST:PORT).
        addr: String,
        /// Why the operating system refused it.
        #[source]
        source: std::io::Error,
    },
    /// The `glint.v1` and health file descriptors built into the binary cannot be served for
    /// reflection: a broken build, not a setting.
    #[error("server reflection: {0}")]
    Reflection(#[from] tonic_reflection::server::Error),
    /// The transport failed while serving (an I/O error on the listener, for instance); the
    /// server has stopped.
    #[error("serving: {0}")]
    Transport(#[from] tonic::transport::Error),
    /// `target` gave no health answer (no connection within the timeout, a refused connection,
    /// an error status), or a child server could not start or ended before it printed its
    /// address ([`process::ServerProcess::spawn`]).
    #[error("{target}: {problem}")]
    Unhealthy {
        /// The server asked: its address, or a child server's command line.
        target: String,
        /// What went wrong, in words.
        problem: String,
    },
    /// A token or TLS file is unusable, or the TLS settings are refused.
    #[error("{0}")]
    Security(String),
}

/// How a server runs.
#[derive(Clone, Debug)]
pub struct ServeConfig {
    /// The `glint.v1` service names this server hosts (e.g. `glint.v1.CalibrationService`):
    /// health reports each of them, and the empty name for the whole server.
    pub services: Vec<&'static str>,
    /// After the shutdown signal, connections get this long to finish their calls.
    pub drain_timeout: Duration,
    /// Token and TLS (default: neither).
    pub security: security::ServerSecurity,
    /// Calls at work per service at most (default: no bound).
    pub call_limits: load::CallLimits,
}

/// Binds `addr` (e.g. `127.0.0.1:50051`, port 0 for any free port).
pub async fn bind(addr: &str) -> Result<TcpListener, ServerError> {
    TcpListener::bind(addr)
        .await
        .map_err(|source| ServerError::Bind {
            addr: addr.into(),
            source,
        })
}

/// Serves `routes` (the stage's services) with health and reflection on `listener` until
/// `shutdown` completes; then every service reports NOT_SERVING at once and open calls get
/// `config.drain_timeout` to finish.
pub async fn serve(
    listener: TcpListener,
    routes: Routes,
    config: ServeConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServerError> {
    let local: Option<SocketAddr> = listener.local_addr().ok();
    let (reporter, health) = tonic_health::server::health_reporter();
    for name in &config.services {
        reporter
            .set_service_status(*name, ServingStatus::Serving)
            .await;
    }
    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(glint_proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()?;
    let routes = routes.add_service(health).add_service(reflection);

    // Shutdown: NOT_SERVING first (probes and the orchestrator stop sending), then stop
    // accepting and drain.
    let (drained_tx, drained_rx) = tokio::sync::oneshot::channel::<()>();
    let services = config.services.clone();
    let signal = async move {
        shutdown.await;
        tracing::info!("shutting down: health NOT_SERVING, draining connections");
        reporter
            .set_service_status("", ServingStatus::NotServing)
            .await;
        for name in &services {
            reporter
                .set_service_status(*name, ServingStatus::NotServing)
                .await;
        }
        let _ = drained_tx.send(());
    };
    tracing::info!(
        "serving {} on {}",
        config.services.join(", "),
        local.map_or_else(|| "?".into(), |a| a.to_string())
    );
    let mut builder = tonic::transport::Server::builder();
    if let Some(tls) = &config.security.tls {
        builder = builder
            .tls_config(tls.config())
            .map_err(|e| ServerError::Security(format!("the TLS settings: {e}")))?;
    }
    let server = builder
        .layer(security::BearerAuthLayer::new(
            config.security.token.clone(),
        ))
        // Inside the token check: a stranger's call takes no place.
        .layer(load::CallLimitLayer::new(&config.call_limits))
        .add_routes(routes)
        .serve_with_incoming_shutdown(TcpListenerStream::new(listener), signal);
    tokio::pin!(server);
    tokio::select! {
        result = &mut server => result?,
        _ = async {
            let _ = drained_rx.await;
            tokio::time::sleep(config.drain_timeout).await;
        } => {
            tracing::warn!("calls still open after {:?}: stopping anyway", config.drain_timeout);
        }
    }
    Ok(())
}

/// Completes on Ctrl-C or SIGTERM (what `docker stop` and Kubernetes send).
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = terminate => {},
    }
}

/// Asks `target` (HOST:PORT or a URI; TLS and token as `security` says) whether `service` (empty: the whole server) is SERVING,
/// within `timeout`.
pub async fn healthcheck(
    target: &str,
    service: &str,
    timeout: Duration,
    security: &security::ClientSecurity,
) -> Result<HealthStatus, ServerError> {
    let unhealthy = |problem: String| ServerError::Unhealthy {
        target: target.into(),
        problem,
    };
    let endpoint = security.endpoint(target)?.connect_timeout(timeout);
    let channel = tokio::time::timeout(timeout, endpoint.connect())
        .await
        .map_err(|_| unhealthy(format!("no connection within {timeout:?}")))?
        .map_err(|e| unhealthy(format!("cannot connect: {e}")))?;
    let mut request = tonic::Request::new(HealthCheckRequest {
        service: service.into(),
    });
    request.set_timeout(timeout);
    let response = HealthClient::new(security.authorize(channel)?)
        .check(request)
        .await
        .map_err(|s| unhealthy(format!("{}: {}", s.code(), s.message())))?;
    Ok(response.into_inner().status())
}

/// Runs `f` on tokio's blocking pool (the libraries are synchronous and use rayon inside); a
/// panic becomes INTERNAL so one bad request cannot take the server down.
pub async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<T, tonic::Status> {
    tokio::task::spawn_blocking(f).await.map_err(|e| {
        tracing::error!("a request's work panicked: {e}");
        tonic::Status::internal("the server failed on this request; see its log")
    })
}
