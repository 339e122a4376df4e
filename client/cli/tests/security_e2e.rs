//! `glint serve all` with a token and TLS, as a process: a session runs through it (the
//! orchestrator reaches the stages over TLS with the same token), a client without the token
//! is refused, `glint healthcheck` passes over TLS without one, and bad flags say what is
//! wrong.

mod common;

use common::argv;

use glint_client::{MockSession, run_mock_session};
use glint_e2e::TestPki;
use glint_geometry::Part;
use glint_orchestrator::session::ViewPolicy;
use glint_proto::v1;
use glint_proto::v1::orchestrator_service_client::OrchestratorServiceClient;
use glint_server::security::{ClientSecurity, ClientTls, Token};

const TOKEN: &str = "cell-7-token-5f2c9a";

#[test]
fn a_session_runs_over_tls_with_a_token_and_strangers_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let pki = TestPki::new();
    pki.write(dir.path());
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, format!("{TOKEN}\n")).unwrap();
    let path = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    let token_path = token_file.to_string_lossy().into_owned();
    let server = common::serve(argv(
        "all --listen 127.0.0.1:0 --token-file {} --tls-cert {} --tls-key \
        {} --tls-ca {}",
        &[
            &token_path,
            &path("server.pem"),
            &path("server.key"),
            &path("ca.pem"),
        ],
    ));
    let tls = ClientTls {
        ca_pem: pki.ca_pem.clone().into_bytes(),
        identity: None,
    };
    let security = ClientSecurity {
        token: Some(Token::new(TOKEN).unwrap()),
        tls: Some(tls.clone()),
    };
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let spec = MockSession {
        part: Part::Zigzag,
        instances: 3,
        policy: ViewPolicy::MaxDistance,
        max_views: 2,
        entropy_threshold_nats: 0.0,
        candidates: 6,
        seed: 2,
        width_px: 320,
        height_px: 256,
        samples_per_pixel: 1,
    };
    let outcome = runtime
        .block_on(run_mock_session(
            &server.addr,
            &server.addr,
            &spec,
            None,
            &security,
            |_, _| {},
        ))
        .unwrap();
    assert!(
        outcome.session.error.is_empty(),
        "{}",
        outcome.session.error
    );
    assert_eq!(outcome.steps.len(), 2);

    // TLS without the token: refused, naming what is missing.
    let no_token = ClientSecurity {
        token: None,
        tls: Some(tls),
    };
    let status = runtime.block_on(async {
        OrchestratorServiceClient::new(
            glint_client::channel(&server.addr, &no_token)
                .await
                .unwrap(),
        )
        .list_sessions(v1::ListSessionsRequest {})
        .await
        .unwrap_err()
    });
    assert_eq!(status.code(), tonic::Code::Unauthenticated, "{status:?}");

    // Probes need no token.
    let probe = common::glint(argv(
        "healthcheck --target {} --tls-ca {} --service \
        glint.v1.OrchestratorService",
        &[&server.addr, &path("ca.pem")],
    ));
    assert!(probe.status.success(), "{}", common::printed(&probe));
}

#[test]
fn bad_security_flags_say_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.pem").to_string_lossy().into_owned();
    // Each command line's `{}` is the missing file.
    let cases = [
        (
            "serve estimation --listen 127.0.0.1:0 --tls-cert {}",
            "--tls-cert and --tls-key go together",
        ),
        (
            "serve estimation --listen 127.0.0.1:0 --token-file {}",
            "--token-file",
        ),
        (
            "serve all --listen 127.0.0.1:0 --tls-cert {} --tls-key {}",
            "--tls-cert",
        ),
        ("healthcheck --tls-cert {}", "--tls-ca"),
    ];
    for (line, expected) in cases {
        let values = vec![missing.as_str(); line.matches("{}").count()];
        let args = argv(line, &values);
        let out = common::glint(&args);
        assert!(!out.status.success(), "{args:?}");
        let said = common::printed(&out);
        assert!(said.contains(expected), "{args:?}: {said}");
    }
}
