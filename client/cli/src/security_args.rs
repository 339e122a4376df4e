//! Token and TLS flags: the servers' (`glint serve …`) and the clients' (`glint session`,
//! `glint healthcheck`, `glint bench fanout --orchestrator`), with environment fallbacks.

use std::path::PathBuf;

use glint_server::security::{ClientSecurity, ClientTls, ServerSecurity, ServerTls, Token};

/// How a server admits calls, and how the orchestrator (alone or in `serve all`) calls the
/// other stages.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct ServerSecurityArgs {
    /// Require `authorization: Bearer <token>` on every call but health checks; the file holds
    /// the token. The orchestrator sends the same token to the stages it calls.
    #[arg(long, global = true, env = "GLINT_TOKEN_FILE")]
    pub token_file: Option<PathBuf>,
    /// Serve TLS with this certificate (PEM; with --tls-key).
    #[arg(long, global = true, env = "GLINT_TLS_CERT")]
    pub tls_cert: Option<PathBuf>,
    /// The certificate's private key (PEM).
    #[arg(long, global = true, env = "GLINT_TLS_KEY")]
    pub tls_key: Option<PathBuf>,
    /// Require client certificates signed by this CA (PEM): mutual TLS.
    #[arg(long, global = true, env = "GLINT_TLS_CLIENT_CA")]
    pub tls_client_ca: Option<PathBuf>,
    /// The orchestrator's calls to the stages go over TLS, trusting this CA (PEM); it presents
    /// --tls-cert/--tls-key as its client certificate.
    #[arg(long, global = true, env = "GLINT_TLS_CA")]
    pub tls_ca: Option<PathBuf>,
}

fn token(file: &Option<PathBuf>) -> anyhow::Result<Option<Token>> {
    Ok(file.as_deref().map(Token::from_file).transpose()?)
}

impl ServerSecurityArgs {
    pub fn server(&self) -> anyhow::Result<ServerSecurity> {
        let tls = match (&self.tls_cert, &self.tls_key) {
            (Some(cert), Some(key)) => Some(ServerTls::from_files(
                cert,
                key,
                self.tls_client_ca.as_deref(),
            )?),
            (None, None) => {
                anyhow::ensure!(
                    self.tls_client_ca.is_none(),
                    "--tls-client-ca: client certificates need TLS: give --tls-cert and --tls-key"
                );
                None
            }
            _ => anyhow::bail!("--tls-cert and --tls-key go together"),
        };
        Ok(ServerSecurity {
            token: token(&self.token_file)?,
            tls,
        })
    }

    /// How the orchestrator calls the stages: the same token, and over TLS trusting
    /// `--tls-ca` (a TLS orchestrator needs it), presenting its own certificate.
    pub fn outbound(&self) -> anyhow::Result<ClientSecurity> {
        anyhow::ensure!(
            self.tls_cert.is_none() || self.tls_ca.is_some(),
            "--tls-ca: the orchestrator calls the stages over TLS; give the CA that signed \
             their certificates"
        );
        let (tls_cert, tls_key) = match self.tls_ca {
            Some(_) => (self.tls_cert.clone(), self.tls_key.clone()),
            None => (None, None),
        };
        ClientSecurityArgs {
            token_file: self.token_file.clone(),
            tls_ca: self.tls_ca.clone(),
            tls_cert,
            tls_key,
        }
        .client()
    }
}

/// How a client reaches a server.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct ClientSecurityArgs {
    /// Send `authorization: Bearer <token>` with the token in this file.
    #[arg(long, global = true, env = "GLINT_TOKEN_FILE")]
    pub token_file: Option<PathBuf>,
    /// Connect over TLS, trusting this CA (PEM).
    #[arg(long, global = true, env = "GLINT_TLS_CA")]
    pub tls_ca: Option<PathBuf>,
    /// A client certificate (PEM, with --tls-key), for servers that require one.
    #[arg(long, global = true, env = "GLINT_TLS_CERT")]
    pub tls_cert: Option<PathBuf>,
    #[arg(long, global = true, env = "GLINT_TLS_KEY")]
    pub tls_key: Option<PathBuf>,
}

impl ClientSecurityArgs {
    pub fn client(&self) -> anyhow::Result<ClientSecurity> {
        let tls = match &self.tls_ca {
            Some(ca) => Some(ClientTls::from_files(
                ca,
                self.tls_cert.as_deref(),
                self.tls_key.as_deref(),
            )?),
            None => {
                anyhow::ensure!(
                    self.tls_cert.is_none() && self.tls_key.is_none(),
                    "--tls-cert: a client certificate needs TLS: give --tls-ca"
                );
                None
            }
        };
        Ok(ClientSecurity {
            token: token(&self.token_file)?,
            tls,
        })
    }
}
