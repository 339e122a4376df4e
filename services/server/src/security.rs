//! Who may call a Glint server, and over what: an optional bearer token on every call and
//! optional TLS (rustls), with client certificates when a client CA is given.
//!
//! - Servers: [`ServerSecurity`] in [`crate::ServeConfig`]; [`BearerAuthLayer`] refuses a call
//!   without `authorization: Bearer <token>` with UNAUTHENTICATED, except the health service
//!   (`grpc.health.v1.Health`), which stays open for container and Kubernetes probes.
//! - Clients: [`ClientSecurity::channel`] connects over TLS when it has a CA and sends the
//!   token on every call ([`AuthChannel`]), so generated clients stay as they are.
//!
//! Tokens are compared in constant time (SHA-256 of both, then every byte), and never
//! printed: [`Token`]'s `Debug` says only that there is one.

use std::future::Future;
use std::path::Path;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use sha2::{Digest, Sha256};
use tonic::body::Body;
use tonic::codegen::http;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Identity, ServerTlsConfig};

use crate::ServerError;

/// Calls to these paths need no token: health, for probes.
const OPEN_PATH_PREFIXES: [&str; 1] = ["/grpc.health.v1.Health/"];

/// A shared secret that callers send as `authorization: Bearer <token>`.
#[derive(Clone)]
pub struct Token {
    secret: Arc<str>,
    digest: [u8; 32],
}

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(<redacted>)")
    }
}

fn read(path: &Path, what: &str) -> Result<Vec<u8>, ServerError> {
    std::fs::read(path)
        .map_err(|e| ServerError::Security(format!("{what} {}: {e}", path.display())))
}

impl Token {
    /// A token from its text, surrounding whitespace trimmed; it must be printable ASCII
    /// (it travels in an HTTP/2 header) and not empty.
    pub fn new(text: &str) -> Result<Self, ServerError> {
        let secret = text.trim();
        if secret.is_empty() {
            return Err(ServerError::Security("the token is empty".into()));
        }
        if !secret.bytes().all(|b| b.is_ascii_graphic() || b == b' ') {
            return Err(ServerError::Security(
                "the token must be printable ASCII".into(),
            ));
        }
        Ok(Self {
            secret: secret.into(),
            digest: Sha256::digest(secret.as_bytes()).into(),
        })
    }

    /// The token in `path` (whitespace around it trimmed).
    pub fn from_file(path: &Path) -> Result<Self, ServerError> {
        let bytes = read(path, "--token-file")?;
        let text = std::str::from_utf8(&bytes).map_err(|_| {
            ServerError::Security(format!("--token-file {}: not UTF-8 text", path.display()))
        })?;
        Self::new(text)
            .map_err(|e| ServerError::Security(format!("--token-file {}: {e}", path.display())))
    }

    /// Whether an `authorization` header's value carries this token. Constant time in the
    /// token: both are hashed and every byte of the digests compared.
    pub fn admits(&self, authorization: &[u8]) -> bool {
        let Some(given) = authorization.strip_prefix(b"Bearer ") else {
            return false;
        };
        let digest: [u8; 32] = Sha256::digest(given).into();
        let difference = digest
            .iter()
            .zip(&self.digest)
            .fold(0u8, |acc, (a, b)| acc | (a ^ b));
        std::hint::black_box(difference) == 0
    }

    fn header(&self) -> Result<http::HeaderValue, ServerError> {
        let mut value = http::HeaderValue::from_str(&format!("Bearer {}", self.secret))
            .map_err(|_| ServerError::Security("the token cannot be sent as a header".into()))?;
        value.set_sensitive(true);
        Ok(value)
    }
}

/// PEM files of a server's TLS identity and, for mutual TLS, the CA its clients' certificates
/// must chain to.
#[derive(Clone, Debug)]
pub struct ServerTls {
    /// The server's certificate chain, PEM.
    pub cert_pem: Vec<u8>,
    /// The server's private key, PEM.
    pub key_pem: Vec<u8>,
    /// The CA (PEM) every client's certificate must chain to; `None`: no client certificate
    /// asked for.
    pub client_ca_pem: Option<Vec<u8>>,
}

impl ServerTls {
    /// Reads the PEM files given as `--tls-cert`, `--tls-key` and, for mutual TLS,
    /// `--tls-client-ca`.
    pub fn from_files(
        cert: &Path,
        key: &Path,
        client_ca: Option<&Path>,
    ) -> Result<Self, ServerError> {
        Ok(Self {
            cert_pem: read(cert, "--tls-cert")?,
            key_pem: read(key, "--tls-key")?,
            client_ca_pem: client_ca.map(|p| read(p, "--tls-client-ca")).transpose()?,
        })
    }

    pub(crate) fn config(&self) -> ServerTlsConfig {
        let config =
            ServerTlsConfig::new().identity(Identity::from_pem(&self.cert_pem, &self.key_pem));
        match &self.client_ca_pem {
            Some(ca) => config.client_ca_root(Certificate::from_pem(ca)),
            None => config,
        }
    }
}

/// How a server admits calls. Default: no token, no TLS.
#[derive(Clone, Debug, Default)]
pub struct ServerSecurity {
    /// The token every call but health must carry; `None`: every caller is admitted.
    pub token: Option<Token>,
    /// The server's TLS identity; `None`: plaintext HTTP/2.
    pub tls: Option<ServerTls>,
}

/// How a client reaches a server: the CA that signed the server's certificate (TLS on), an
/// optional client certificate, and the token.
#[derive(Clone, Debug, Default)]
pub struct ClientSecurity {
    /// The token sent on every call; `None`: none is sent.
    pub token: Option<Token>,
    /// The TLS settings; `None`: plaintext (`http://`).
    pub tls: Option<ClientTls>,
}

/// A client's TLS settings.
#[derive(Clone, Debug)]
pub struct ClientTls {
    /// The CA certificate (PEM) the server's certificate must chain to.
    pub ca_pem: Vec<u8>,
    /// Certificate and key (PEM) to present, for servers that require client certificates.
    pub identity: Option<(Vec<u8>, Vec<u8>)>,
}

impl ClientTls {
    /// Reads the CA given as `--tls-ca` and, for servers that require client certificates,
    /// the certificate and key given as `--tls-cert` and `--tls-key` (both or neither).
    pub fn from_files(
        ca: &Path,
        cert: Option<&Path>,
        key: Option<&Path>,
    ) -> Result<Self, ServerError> {
        let identity = match (cert, key) {
            (Some(c), Some(k)) => Some((read(c, "--tls-cert")?, read(k, "--tls-key")?)),
            (None, None) => None,
            _ => {
                return Err(ServerError::Security(
                    "--tls-cert and --tls-key go together".into(),
                ));
            }
        };
        Ok(Self {
            ca_pem: read(ca, "--tls-ca")?,
            identity,
        })
    }
}

impl ClientSecurity {
    /// `addr` (HOST:PORT or a URI) as a URI: `https://` with TLS, else `http://`.
    pub fn uri(&self, addr: &str) -> String {
        match (addr.split_once("://"), &self.tls) {
            (Some(("http", rest)), Some(_)) => format!("https://{rest}"),
            (Some(_), _) => addr.to_owned(),
            (None, Some(_)) => format!("https://{addr}"),
            (None, None) => format!("http://{addr}"),
        }
    }

    /// The endpoint of `addr`, with TLS when configured (the server's name is the URI's host).
    pub fn endpoint(&self, addr: &str) -> Result<tonic::transport::Endpoint, ServerError> {
        let uri = self.uri(addr);
        let endpoint = tonic::transport::Endpoint::from_shared(uri.clone()).map_err(|e| {
            ServerError::Security(format!("{addr}: not an address ({e}); give HOST:PORT"))
        })?;
        match &self.tls {
            None => Ok(endpoint),
            Some(tls) => {
                let mut config =
                    ClientTlsConfig::new().ca_certificate(Certificate::from_pem(&tls.ca_pem));
                if let Some((cert, key)) = &tls.identity {
                    config = config.identity(Identity::from_pem(cert, key));
                }
                endpoint
                    .tls_config(config)
                    .map_err(|e| ServerError::Security(format!("{uri}: TLS settings: {e}")))
            }
        }
    }

    /// `channel` sending this token on every call.
    pub fn authorize(&self, channel: Channel) -> Result<AuthChannel, ServerError> {
        Ok(AuthChannel {
            inner: channel,
            authorization: self.token.as_ref().map(Token::header).transpose()?,
        })
    }
}

/// A channel that adds `authorization: Bearer <token>` to every call (when it has a token).
#[derive(Clone, Debug)]
pub struct AuthChannel {
    inner: Channel,
    authorization: Option<http::HeaderValue>,
}

impl tonic::codegen::Service<http::Request<Body>> for AuthChannel {
    type Response = http::Response<Body>;
    type Error = tonic::transport::Error;
    type Future = <Channel as tonic::codegen::Service<http::Request<Body>>>::Future;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        tonic::codegen::Service::poll_ready(&mut self.inner, cx)
    }

    fn call(&mut self, mut request: http::Request<Body>) -> Self::Future {
        if let Some(value) = &self.authorization {
            request
                .headers_mut()
                .insert(http::header::AUTHORIZATION, value.clone());
        }
        tonic::codegen::Service::call(&mut self.inner, request)
    }
}

/// The server side: refuses calls without the token (health excepted).
#[derive(Clone, Debug, Default)]
pub struct BearerAuthLayer {
    token: Option<Token>,
}

impl BearerAuthLayer {
    /// The layer admitting calls that carry `token`; `None` admits every call.
    pub fn new(token: Option<Token>) -> Self {
        Self { token }
    }
}

impl<S> tower_layer::Layer<S> for BearerAuthLayer {
    type Service = BearerAuth<S>;

    fn layer(&self, inner: S) -> Self::Service {
        BearerAuth {
            inner,
            token: self.token.clone(),
        }
    }
}

/// [`BearerAuthLayer`]'s service.
#[derive(Clone, Debug)]
pub struct BearerAuth<S> {
    inner: S,
    token: Option<Token>,
}

type BoxFuture<T> = Pin<Box<dyn Future<Output = T> + Send>>;

impl<S, B> tonic::codegen::Service<http::Request<B>> for BearerAuth<S>
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
        let admitted = match &self.token {
            None => true,
            Some(token) => {
                OPEN_PATH_PREFIXES
                    .iter()
                    .any(|p| request.uri().path().starts_with(p))
                    || request
                        .headers()
                        .get(http::header::AUTHORIZATION)
                        .is_some_and(|v| token.admits(v.as_bytes()))
            }
        };
        if admitted {
            Box::pin(self.inner.call(request))
        } else {
            let refused = tonic::Status::unauthenticated(
                "authorization: this server needs `authorization: Bearer <token>` with its token \
                 (clients: --token-file)",
            );
            Box::pin(std::future::ready(Ok(refused.into_http())))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_token_admits_only_itself() {
        let token = Token::new("  s3cret-token\n").unwrap();
        assert!(token.admits(b"Bearer s3cret-token"));
        assert!(!token.admits(b"Bearer s3cret-tokeN"));
        assert!(!token.admits(b"Bearer s3cret-token "));
        assert!(!token.admits(b"bearer s3cret-token"));
        assert!(!token.admits(b"s3cret-token"));
        assert!(!token.admits(b""));
        assert_eq!(format!("{token:?}"), "Token(<redacted>)");
    }

    #[test]
    fn bad_tokens_are_refused_with_a_reason() {
        assert!(Token::new(" \n").is_err());
        assert!(Token::new("tab\there").is_err());
        assert!(Token::new("é").is_err());
        let missing = Token::from_file(Path::new("/nonexistent/token")).unwrap_err();
        assert!(
            missing
                .to_string()
                .contains("--token-file /nonexistent/token")
        );
    }

    #[test]
    fn uris_follow_the_tls_setting() {
        let plain = ClientSecurity::default();
        let tls = ClientSecurity {
            token: None,
            tls: Some(ClientTls {
                ca_pem: Vec::new(),
                identity: None,
            }),
        };
        assert_eq!(plain.uri("127.0.0.1:1"), "http://127.0.0.1:1");
        assert_eq!(tls.uri("127.0.0.1:1"), "https://127.0.0.1:1");
        assert_eq!(tls.uri("http://h:1"), "https://h:1");
        assert_eq!(plain.uri("https://h:1"), "https://h:1");
    }
}
