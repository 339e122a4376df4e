"""A secured deployment from Python: `glint serve all` with a bearer token (`--token-file`), with
TLS (`--tls-cert --tls-key`), and with mutual TLS (`--tls-client-ca`), reached through
`GlintClient(token=/token_file=, tls_ca=, tls_cert=, tls_key=)` and the example's flags.

Calls without the token, or with a wrong one, are UNAUTHENTICATED; health checks stay open;
reflection needs the token; TLS needs the right CA (and, for mutual TLS, a client certificate);
the token appears in no message and no log. The certificates are made here (a throw-away CA,
a server certificate for 127.0.0.1 and localhost, a client certificate) with `cryptography`."""

import datetime
import ipaddress
import pathlib
import subprocess
import sys

import grpc
import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from glint_client import GlintClient, GlintError, SecurityConfigError, SessionState, read_token_file
from glint_client.security import BearerToken

from conftest import CLIENT, Server, server_env

EXAMPLE = CLIENT / "examples" / "active_session.py"
TOKEN = "cell-7-py-token-4e1d0b"
#: The smallest session worth running: one view of a small mock bin.
TINY_SESSION = [
    "--part", "zigzag", "--instances", "4", "--seed", "1", "--resolution", "640x512", "--spp", "1",
    "--candidates", "4", "--max-views", "1", "--policy", "max-distance",
]
SERVING = 1  # grpc.health.v1.HealthCheckResponse.ServingStatus.SERVING


# --- a throw-away PKI -----------------------------------------------------------------------

def _key():
    return ec.generate_private_key(ec.SECP256R1())


def _pem_key(key):
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())


def _certificate(subject_cn, key, issuer_cert=None, issuer_key=None, ca=False, names=()):
    now = datetime.datetime.now(datetime.timezone.utc)
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject_cn)])
    builder = (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(issuer_cert.subject if issuer_cert else subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True)
    )
    if ca:
        builder = builder.add_extension(
            x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True, content_commitment=False,
                          key_encipherment=False, data_encipherment=False, key_agreement=False,
                          encipher_only=False, decipher_only=False),
            critical=True,
        ).add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
    else:
        sans = [x509.IPAddress(ipaddress.ip_address(n)) if n[0].isdigit() else x509.DNSName(n) for n in names]
        builder = builder.add_extension(x509.SubjectAlternativeName(sans), critical=False).add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(issuer_key.public_key()), critical=False
        )
    return builder.sign(issuer_key or key, hashes.SHA256())


def write_pki(directory):
    """`ca.pem`, `server.pem`/`server.key` (127.0.0.1, localhost), `client.pem`/`client.key`
    signed by the CA, and `other-ca.pem` (a CA that signed nothing here) in `directory`."""
    files = {}

    def write(name, data):
        path = directory / name
        path.write_bytes(data)
        files[name] = str(path)

    ca_key = _key()
    ca = _certificate("Glint test CA", ca_key, ca=True)
    write("ca.pem", ca.public_bytes(serialization.Encoding.PEM))
    for who, names in (("server", ("127.0.0.1", "localhost")), ("client", ("glint-client",))):
        key = _key()
        cert = _certificate(f"glint {who}", key, issuer_cert=ca, issuer_key=ca_key, names=names)
        write(f"{who}.pem", cert.public_bytes(serialization.Encoding.PEM))
        write(f"{who}.key", _pem_key(key))
    other_key = _key()
    write("other-ca.pem", _certificate("Another CA", other_key, ca=True).public_bytes(serialization.Encoding.PEM))
    return files


@pytest.fixture(scope="module")
def secrets(tmp_path_factory):
    """The PKI's files and `token` (the token with a trailing newline, as an editor saves it)
    and `wrong-token`."""
    directory = tmp_path_factory.mktemp("secrets")
    files = write_pki(directory)
    (directory / "token").write_text(f"  {TOKEN}\n")
    (directory / "wrong-token").write_text("cell-7-py-token-4e1d0c\n")
    files["token"] = str(directory / "token")
    files["wrong-token"] = str(directory / "wrong-token")
    return files


def _serve(tmp_path_factory, name, args):
    server = Server(["all", *args], tmp_path_factory.mktemp(name) / f"{name}.log")
    try:
        yield server
    finally:
        server.stop()
        assert TOKEN not in pathlib.Path(server.log_path).read_text(), "the server logged its token"


@pytest.fixture(scope="module")
def token_server(tmp_path_factory, secrets):
    """`glint serve all --token-file` (plaintext)."""
    yield from _serve(tmp_path_factory, "token", ["--token-file", secrets["token"]])


@pytest.fixture(scope="module")
def tls_server(tmp_path_factory, secrets):
    """`glint serve all` over TLS with a token (the orchestrator reaches the stages over TLS,
    trusting `--tls-ca`)."""
    yield from _serve(tmp_path_factory, "tls", [
        "--token-file", secrets["token"], "--tls-cert", secrets["server.pem"], "--tls-key", secrets["server.key"],
        "--tls-ca", secrets["ca.pem"],
    ])


@pytest.fixture(scope="module")
def mtls_server(tmp_path_factory, secrets):
    """`glint serve all` over mutual TLS with a token: clients present a certificate signed by
    `--tls-client-ca` (the orchestrator presents its server certificate to the stages)."""
    yield from _serve(tmp_path_factory, "mtls", [
        "--token-file", secrets["token"], "--tls-cert", secrets["server.pem"], "--tls-key", secrets["server.key"],
        "--tls-client-ca", secrets["ca.pem"], "--tls-ca", secrets["ca.pem"],
    ])


def list_sessions_error(**client_args):
    """The GlintError that ListSessions raises with these client settings."""
    with GlintClient(timeout_s=10, **client_args) as glint:
        with pytest.raises(GlintError) as error:
            glint.list_sessions()
    assert error.value.rpc == "ListSessions"
    assert TOKEN not in str(error.value)
    return error.value


# --- health and reflection over raw calls ----------------------------------------------------
# grpcio-tools ships no grpc/health/v1/health.proto, and both messages used here have one field,
# so they are written by hand rather than adding grpcio-health-checking: HealthCheckRequest
# {string service = 1}, HealthCheckResponse {ServingStatus status = 1}.

def health_status(channel, service=""):
    name = service.encode()
    request = b"\x0a" + bytes([len(name)]) + name if name else b""
    reply = channel.unary_unary("/grpc.health.v1.Health/Check")(request, timeout=10)
    assert reply[:1] == b"\x08" and len(reply) == 2, reply
    return reply[1]


def list_services(channel, metadata=None):
    """grpc.reflection.v1 ListServices (`ServerReflectionRequest {list_services = 7: ""}`): the
    raw reply."""
    call = channel.stream_stream("/grpc.reflection.v1.ServerReflection/ServerReflectionInfo")
    return b"".join(call(iter([b"\x3a\x00"]), timeout=10, metadata=metadata))


# --- a token -----------------------------------------------------------------------------------

def test_calls_need_the_right_token(token_server, secrets):
    addr = token_server.addr
    for refused in (dict(), dict(token_file=secrets["wrong-token"]), dict(token="Bearer " + TOKEN), dict(token=TOKEN + "x")):
        error = list_sessions_error(target=addr, **refused)
        assert error.code == grpc.StatusCode.UNAUTHENTICATED, (refused, error)
        assert "authorization" in error.message
    with GlintClient(addr, token_file=secrets["token"]) as glint:
        assert glint.authenticated and not glint.tls
        assert isinstance(glint.list_sessions(), list)
        # A server stream (RunSession) carries the token too: refused for the id, not for the token.
        with pytest.raises(GlintError) as error:
            list(glint.run_session("s-no-such-session", timeout_s=10))
        assert error.value.code_name == "NOT_FOUND", error.value
    with GlintClient(addr, token=TOKEN) as glint:
        assert isinstance(glint.list_sessions(), list)
    with GlintClient(addr) as glint:
        with pytest.raises(GlintError) as error:
            list(glint.run_session("s-no-such-session", timeout_s=10))
        assert error.value.code_name == "UNAUTHENTICATED"


def test_health_stays_open_and_reflection_needs_the_token(token_server):
    with grpc.insecure_channel(token_server.addr) as channel:
        assert health_status(channel) == SERVING
        assert health_status(channel, "glint.v1.OrchestratorService") == SERVING
        with pytest.raises(grpc.RpcError) as error:
            list_services(channel)
        assert error.value.code() == grpc.StatusCode.UNAUTHENTICATED
        assert b"glint.v1.OrchestratorService" in list_services(channel, [("authorization", f"Bearer {TOKEN}")])


def test_the_token_is_never_shown(secrets, tmp_path):
    assert read_token_file(secrets["token"]) == TOKEN  # surrounding whitespace trimmed
    assert TOKEN not in repr(BearerToken(TOKEN))
    with GlintClient("127.0.0.1:9", token=TOKEN) as glint:
        assert TOKEN not in repr(glint) and TOKEN not in repr(vars(glint))
    # A token the server could not accept is refused here, without echoing it.
    bad = tmp_path / "bad-token"
    bad.write_text("half-a-token\tand-a-tab\n")
    with pytest.raises(SecurityConfigError) as error:
        GlintClient("127.0.0.1:9", token_file=bad)
    assert str(bad) in str(error.value) and "printable ASCII" in str(error.value)
    assert "half-a-token" not in str(error.value)


@pytest.mark.parametrize(
    "settings, message",
    [
        (dict(token_file="/nonexistent/token"), "token file /nonexistent/token: No such file or directory"),
        (dict(token_file="EMPTY"), "is empty"),
        (dict(token_file="DIR"), "token file"),
        (dict(token=TOKEN, token_file="TOKEN"), "token or token_file, not both"),
        (dict(tls_ca="/nonexistent/ca.pem"), "TLS CA file /nonexistent/ca.pem: No such file or directory"),
        (dict(tls_ca="TOKEN"), "not a PEM file"),
        (dict(tls_ca="CA", tls_cert="CERT"), "tls_cert and tls_key go together"),
        (dict(tls_cert="CERT", tls_key="KEY"), "needs TLS: give tls_ca"),
        (dict(tls_ca="CA", tls_cert="CERT", tls_key="/nonexistent/client.key"), "TLS key file /nonexistent/client.key"),
        (dict(target="https://127.0.0.1:9"), "https:// needs tls_ca"),
    ],
)
def test_unusable_security_settings_say_what_is_wrong(secrets, tmp_path, settings, message):
    (tmp_path / "empty").write_text(" \n")
    names = {"EMPTY": str(tmp_path / "empty"), "DIR": str(tmp_path), "TOKEN": secrets["token"],
             "CA": secrets["ca.pem"], "CERT": secrets["client.pem"], "KEY": secrets["client.key"]}
    settings = {k: names.get(v, v) for k, v in settings.items()}
    settings.setdefault("target", "127.0.0.1:9")
    with pytest.raises(SecurityConfigError) as error:  # a ValueError
        GlintClient(**settings)
    assert message in str(error.value)
    assert TOKEN not in str(error.value)


# --- TLS -----------------------------------------------------------------------------------------

def test_tls_needs_the_right_ca_and_the_token(tls_server, token_server, secrets):
    port = tls_server.addr.rsplit(":", 1)[1]
    # The server's certificate names 127.0.0.1 and localhost; an https:// target is taken too.
    for target in (tls_server.addr, f"localhost:{port}", f"https://{tls_server.addr}"):
        with GlintClient(target, token_file=secrets["token"], tls_ca=secrets["ca.pem"]) as glint:
            assert glint.tls and isinstance(glint.list_sessions(), list)
    with grpc.secure_channel(tls_server.addr, grpc.ssl_channel_credentials(open(secrets["ca.pem"], "rb").read())) as channel:
        assert health_status(channel, "glint.v1.OrchestratorService") == SERVING  # no token
    # Over TLS without the token, or with a wrong one: refused for the token.
    assert list_sessions_error(target=tls_server.addr, tls_ca=secrets["ca.pem"]).code_name == "UNAUTHENTICATED"
    assert list_sessions_error(target=tls_server.addr, tls_ca=secrets["ca.pem"],
                               token_file=secrets["wrong-token"]).code_name == "UNAUTHENTICATED"
    # Plaintext to the TLS port, TLS trusting another CA, TLS to the plaintext server: no connection.
    for settings in (
        dict(target=tls_server.addr, token_file=secrets["token"]),
        dict(target=tls_server.addr, token_file=secrets["token"], tls_ca=secrets["other-ca.pem"]),
        dict(target=token_server.addr, token_file=secrets["token"], tls_ca=secrets["ca.pem"]),
    ):
        error = list_sessions_error(**settings)
        assert error.code_name == "UNAVAILABLE", (settings, error)


def run_example(*args):
    run = subprocess.run([sys.executable, str(EXAMPLE), *args], capture_output=True, text=True, timeout=120,
                         env=server_env())
    assert TOKEN not in run.stdout + run.stderr
    return run


def test_the_example_runs_a_session_over_tls_with_a_token(tls_server, secrets):
    """The orchestrator reaches the camera and the estimation stage over TLS with the token."""
    run = run_example("--target", tls_server.addr, "--token-file", secrets["token"], "--tls-ca", secrets["ca.pem"],
                      *TINY_SESSION)
    assert run.returncode == 0, run.stderr
    assert "BUDGET_SPENT, 1 views" in run.stdout, run.stdout
    # Without the token: one line, exit 1, saying what is missing.
    run = run_example("--target", tls_server.addr, "--tls-ca", secrets["ca.pem"], *TINY_SESSION)
    assert run.returncode == 1, (run.stdout, run.stderr)
    assert len(run.stderr.strip().splitlines()) == 1 and "Traceback" not in run.stderr, run.stderr
    assert "SetUpScene: UNAUTHENTICATED" in run.stderr and "--token-file" in run.stderr
    # The token file from the environment, as the servers take theirs.
    env = {**server_env(), "GLINT_TOKEN_FILE": secrets["wrong-token"]}
    run = subprocess.run([sys.executable, str(EXAMPLE), "--target", tls_server.addr, "--tls-ca", secrets["ca.pem"],
                          *TINY_SESSION], capture_output=True, text=True, timeout=120, env=env)
    assert run.returncode == 1 and f"the token in {secrets['wrong-token']} was refused" in run.stderr, run.stderr


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--token-file", "/nonexistent/token"], "token file /nonexistent/token: No such file or directory"),
        (["--tls-ca", "/nonexistent/ca.pem"], "TLS CA file /nonexistent/ca.pem"),
        (["--tls-cert", "client.pem"], "--tls-cert and --tls-key go together"),
        (["--tls-cert", "client.pem", "--tls-key", "client.key"], "--tls-cert needs --tls-ca"),
    ],
)
def test_the_example_rejects_bad_security_flags_in_one_line(flags, message):
    run = run_example("--target", "127.0.0.1:9", *flags)
    assert run.returncode == 2, (run.stdout, run.stderr)
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert message in run.stderr


def test_mutual_tls_needs_a_client_certificate(mtls_server, secrets):
    tls = dict(target=mtls_server.addr, token_file=secrets["token"], tls_ca=secrets["ca.pem"])
    assert list_sessions_error(**tls).code_name == "UNAVAILABLE"  # no client certificate: no handshake
    with GlintClient(**tls, tls_cert=secrets["client.pem"], tls_key=secrets["client.key"]) as glint:
        # One view through the orchestrator, which presents its own certificate to the stages.
        glint.set_up_mock_bin("zigzag", instances=4, seed=1, width_px=640, height_px=512, samples_per_pixel=1)
        candidates = glint.candidate_views(4)
        truth = glint.ground_truth(visibility_from_t_w_c=candidates[0])  # evaluation only
        target = max(range(len(truth.t_w_o)), key=lambda i: truth.visibility[i].px_count_visib)
        session_id = glint.start_session("zigzag", truth.t_w_o[target], candidates_t_w_c=candidates,
                                         policy="max-distance", max_views=1)
        final = list(glint.run_session(session_id, timeout_s=120))[-1]
        assert final.state == SessionState.BUDGET_SPENT and final.error == "", final.error
        assert session_id in [s.session_id for s in glint.list_sessions()]
