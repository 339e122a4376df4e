//! Glint's workspace end-to-end tests live in `tests/`; this library holds what they share:
//! a stage server started on a free loopback port, and the fuzz targets' bodies
//! ([`fuzz_cases`]), which `fuzz/` runs under libFuzzer and `tests/fuzz_corpus.rs` replays.

pub mod fuzz_cases;

use std::time::Duration;

use glint_server::load::CallLimits;
use glint_server::security::{ClientSecurity, ServerSecurity};
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
        Self::start_secured(
            routes,
            services,
            ServerSecurity::default(),
            &ClientSecurity::default(),
        )
        .await
    }

    /// As [`Self::start_services`], admitting calls as `security` says; `client` is how the
    /// health check reaches it. `target` is then `https://` when the server has TLS.
    pub async fn start_secured(
        routes: tonic::service::Routes,
        services: &[&'static str],
        security: ServerSecurity,
        client: &ClientSecurity,
    ) -> Self {
        Self::start_with(routes, services, security, client, CallLimits::default()).await
    }

    /// As [`Self::start_secured`], with `call_limits`.
    pub async fn start_with(
        routes: tonic::service::Routes,
        services: &[&'static str],
        security: ServerSecurity,
        client: &ClientSecurity,
        call_limits: CallLimits,
    ) -> Self {
        let service = services[0];
        let listener = glint_server::bind("127.0.0.1:0").await.unwrap();
        let target = client.uri(&listener.local_addr().unwrap().to_string());
        let (stop, stop_rx) = oneshot::channel::<()>();
        let task = tokio::spawn(glint_server::serve(
            listener,
            routes,
            ServeConfig {
                services: services.to_vec(),
                drain_timeout: Duration::from_millis(300),
                security,
                call_limits,
            },
            async {
                let _ = stop_rx.await;
            },
        ));
        let status = glint_server::healthcheck(&target, service, Duration::from_secs(5), client)
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

/// A throwaway PKI for TLS tests, as PEM: a CA, a server certificate for `127.0.0.1` and
/// `localhost` signed by it, and a client certificate signed by it.
pub struct TestPki {
    pub ca_pem: String,
    pub server_cert_pem: String,
    pub server_key_pem: String,
    pub client_cert_pem: String,
    pub client_key_pem: String,
}

impl TestPki {
    pub fn new() -> Self {
        use rcgen::{BasicConstraints, CertificateParams, IsCa, KeyPair};
        let ca_key = KeyPair::generate().unwrap();
        let mut ca = CertificateParams::new(Vec::<String>::new()).unwrap();
        ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        let ca_cert = ca.self_signed(&ca_key).unwrap();
        let leaf = |names: &[&str]| {
            let key = KeyPair::generate().unwrap();
            let names = names.iter().map(|n| n.to_string()).collect::<Vec<_>>();
            let cert = CertificateParams::new(names)
                .unwrap()
                .signed_by(&key, &ca_cert, &ca_key)
                .unwrap();
            (cert.pem(), key.serialize_pem())
        };
        let (server_cert_pem, server_key_pem) = leaf(&["127.0.0.1", "localhost"]);
        let (client_cert_pem, client_key_pem) = leaf(&["glint-client"]);
        Self {
            ca_pem: ca_cert.pem(),
            server_cert_pem,
            server_key_pem,
            client_cert_pem,
            client_key_pem,
        }
    }

    /// Writes `ca.pem`, `server.pem`, `server.key`, `client.pem`, `client.key` into `dir`.
    pub fn write(&self, dir: &std::path::Path) {
        for (name, pem) in [
            ("ca.pem", &self.ca_pem),
            ("server.pem", &self.server_cert_pem),
            ("server.key", &self.server_key_pem),
            ("client.pem", &self.client_cert_pem),
            ("client.key", &self.client_key_pem),
        ] {
            std::fs::write(dir.join(name), pem).unwrap();
        }
    }
}

impl Default for TestPki {
    fn default() -> Self {
        Self::new()
    }
}
