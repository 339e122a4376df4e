//! Glint's workspace end-to-end tests live in `tests/`; this library holds what they share:
//! a stage server started on a free loopback port.

use std::time::Duration;

use glint_server::{HealthStatus, ServeConfig, ServerError};
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// A server running in this process on `127.0.0.1`, until [`TestServer::stop`].
pub struct TestServer {
    /// `http://127.0.0.1:PORT`.
    pub target: String,
    stop: oneshot::Sender<()>,
    task: JoinHandle<Result<(), ServerError>>,
}

impl TestServer {
    /// Starts `routes` with health for `service` and waits until it answers SERVING.
    pub async fn start(routes: tonic::service::Routes, service: &'static str) -> Self {
        Self::start_services(routes, &[service]).await
    }

    /// Starts `routes` with health for each of `services` (a stage serving several, like the
    /// mock camera) and waits until the first answers SERVING.
    pub async fn start_services(routes: tonic::service::Routes, services: &[&'static str]) -> Self {
        let service = services[0];
        let listener = glint_server::bind("127.0.0.1:0").await.unwrap();
        let target = format!("http://{}", listener.local_addr().unwrap());
        let (stop, stop_rx) = oneshot::channel::<()>();
        let task = tokio::spawn(glint_server::serve(
            listener,
            routes,
            ServeConfig {
                services: services.to_vec(),
                drain_timeout: Duration::from_millis(300),
            },
            async {
                let _ = stop_rx.await;
            },
        ));
        let status = glint_server::healthcheck(&target, service, Duration::from_secs(5))
            .await
            .unwrap();
        assert_eq!(status, HealthStatus::Serving);
        Self { target, stop, task }
    }

    /// Begins the shutdown; the returned task ends when the server has drained.
    pub fn stop(self) -> JoinHandle<Result<(), ServerError>> {
        let _ = self.stop.send(());
        self.task
    }
}
