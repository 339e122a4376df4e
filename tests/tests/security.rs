//! Bearer tokens and TLS on a real server over loopback (the estimation service stands for
//! every stage: the checks live in `glint-server`, shared by all). Without the token a call is
//! UNAUTHENTICATED and health stays open; over TLS only a client trusting the CA gets through,
//! and with a client CA only a client with a certificate.

use std::time::Duration;

use glint_e2e::{TestPki, TestServer};
use glint_estimation::server::{Estimation, SERVICE_NAME};
use glint_proto::v1;
use glint_proto::v1::estimation_service_client::EstimationServiceClient;
use glint_server::security::{ClientSecurity, ClientTls, ServerSecurity, ServerTls, Token};
use tonic::Code;

fn routes() -> tonic::service::Routes {
    tonic::service::Routes::new(Estimation::default().into_service())
}

/// The entropy of an identity information: a cheap call whose answer proves it got through.
async fn entropy(target: &str, security: &ClientSecurity) -> Result<f64, tonic::Status> {
    let channel = security
        .endpoint(target)
        .unwrap()
        .connect_timeout(Duration::from_secs(5))
        .connect()
        .await
        .map_err(|e| tonic::Status::unavailable(format!("{e:?}")))?;
    let mut identity = Vec::with_capacity(21);
    for i in 0..6 {
        for j in i..6 {
            identity.push(if i == j { 1.0 } else { 0.0 });
        }
    }
    let response = EstimationServiceClient::new(security.authorize(channel).unwrap())
        .pose_entropy(v1::PoseEntropyRequest {
            information: Some(v1::SymmetricMatrix6 { upper: identity }),
        })
        .await?;
    Ok(response.into_inner().entropy_nats)
}

fn with_token(token: &str) -> ClientSecurity {
    ClientSecurity {
        token: Some(Token::new(token).unwrap()),
        tls: None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn calls_need_the_token_and_health_does_not() {
    let token = Token::new("a-long-random-token-0123456789").unwrap();
    let server = TestServer::start_secured(
        routes(),
        &[SERVICE_NAME],
        ServerSecurity {
            token: Some(token),
            tls: None,
        },
        // Health answers without a token (start_secured waits for SERVING this way).
        &ClientSecurity::default(),
    )
    .await;
    let none = entropy(&server.target, &ClientSecurity::default()).await;
    assert_eq!(none.unwrap_err().code(), Code::Unauthenticated);
    let wrong = entropy(&server.target, &with_token("a-long-random-token-012345678")).await;
    let wrong = wrong.unwrap_err();
    assert_eq!(wrong.code(), Code::Unauthenticated);
    assert!(wrong.message().contains("--token-file"), "{wrong:?}");
    let h = entropy(
        &server.target,
        &with_token("a-long-random-token-0123456789"),
    )
    .await
    .unwrap();
    assert!(h.is_finite());
    server.stop().await.unwrap().unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_admits_only_clients_that_trust_the_ca_and_mutual_tls_only_those_with_a_certificate() {
    let pki = TestPki::new();
    let other = TestPki::new();
    let client = |pki: &TestPki, identity: bool| ClientSecurity {
        token: None,
        tls: Some(ClientTls {
            ca_pem: pki.ca_pem.clone().into_bytes(),
            identity: identity.then(|| {
                (
                    pki.client_cert_pem.clone().into_bytes(),
                    pki.client_key_pem.clone().into_bytes(),
                )
            }),
        }),
    };
    let server_tls = |client_ca: bool| ServerTls {
        cert_pem: pki.server_cert_pem.clone().into_bytes(),
        key_pem: pki.server_key_pem.clone().into_bytes(),
        client_ca_pem: client_ca.then(|| pki.ca_pem.clone().into_bytes()),
    };

    // Server certificates only.
    let server = TestServer::start_secured(
        routes(),
        &[SERVICE_NAME],
        ServerSecurity {
            token: None,
            tls: Some(server_tls(false)),
        },
        &client(&pki, false),
    )
    .await;
    assert!(server.target.starts_with("https://"), "{}", server.target);
    let addr = server.target.trim_start_matches("https://").to_owned();
    assert!(
        entropy(&addr, &client(&pki, false))
            .await
            .unwrap()
            .is_finite()
    );
    // Plain text to a TLS port, and TLS trusting another CA, get nowhere.
    assert!(entropy(&addr, &ClientSecurity::default()).await.is_err());
    assert!(entropy(&addr, &client(&other, false)).await.is_err());
    server.stop().await.unwrap().unwrap();

    // Client certificates required.
    let server = TestServer::start_secured(
        routes(),
        &[SERVICE_NAME],
        ServerSecurity {
            token: None,
            tls: Some(server_tls(true)),
        },
        &client(&pki, true),
    )
    .await;
    let addr = server.target.trim_start_matches("https://").to_owned();
    assert!(
        entropy(&addr, &client(&pki, true))
            .await
            .unwrap()
            .is_finite()
    );
    assert!(entropy(&addr, &client(&pki, false)).await.is_err());
    // A certificate from another CA is refused too.
    let mut foreign = client(&pki, true);
    if let Some(tls) = &mut foreign.tls {
        tls.identity = Some((
            other.client_cert_pem.clone().into_bytes(),
            other.client_key_pem.clone().into_bytes(),
        ));
    }
    assert!(entropy(&addr, &foreign).await.is_err());
    server.stop().await.unwrap().unwrap();
}
