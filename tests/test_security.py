"""The secured fleet: an in-process router with the config deploy/scripts/gen-dev-certs.sh makes
from deploy/zenoh/secure/router.json5 (TLS with client certificates, user and password, access
control by identity: one per camera, bound to its robot) and certificates made at test time."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zenoh

from asnn.stimuli import make_scene
from clients.alerts import WarningListener
from service import keys
from service.core import WorkerCore
from service.demo import free_port
from service.messages import Frame, Response, decode_frame, encode
from service.worker import Worker, live_workers, query_status

from netutil import Responses, wait_for

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "deploy" / "scripts" / "gen-dev-certs.sh"
ROUTER = ROOT / "deploy" / "zenoh" / "secure" / "router.json5"
QUIET = 1.5  # seconds to wait for a message that must not arrive

pytestmark = pytest.mark.skipif(not (shutil.which("openssl") and shutil.which("bash")),
                                reason="needs openssl and bash for the certificates")


ROBOTS = ("r1", "r2")


def generate(directory: Path) -> Path:
    subprocess.run(["bash", str(SCRIPT), "--robots", ",".join(ROBOTS), str(directory)],
                   check=True, capture_output=True, timeout=180)
    return directory


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    return generate(tmp_path_factory.mktemp("secrets"))


@pytest.fixture(scope="module")
def rogue(tmp_path_factory):
    """Another CA with certificates for the same roles: valid, but not trusted by the router."""
    return generate(tmp_path_factory.mktemp("rogue"))


def set_json(conf: zenoh.Config, key: str, value) -> None:
    conf.insert_json5(key, json.dumps(value))


def router_config(certs: Path, port: int) -> zenoh.Config:
    """The generated router config (paths already in ``certs``), on a free loopback port."""
    conf = zenoh.Config.from_file(str(certs / "router" / "router.json5"))
    set_json(conf, "listen/endpoints", [f"tls/127.0.0.1:{port}"])
    return conf


def client_config(certs: Path, role: str, port: int, *, password: str | None = None,
                  ca: Path | None = None, cert_from: Path | None = None) -> zenoh.Config:
    """The generated config of ``role``, pointed at the test router (optionally with another
    password, another trusted CA, or the client certificate of another CA)."""
    conf = zenoh.Config.from_file(str(certs / role / f"{role}.json5"))
    set_json(conf, "connect/endpoints", [f"tls/127.0.0.1:{port}"])
    set_json(conf, "timestamping/enabled", True)
    if password is not None:
        set_json(conf, "transport/auth/usrpwd/password", password)
    if ca is not None:
        set_json(conf, "transport/link/tls/root_ca_certificate", str(ca))
    if cert_from is not None:
        set_json(conf, "transport/link/tls/connect_certificate",
                 str(cert_from / role / f"{role}.pem"))
        set_json(conf, "transport/link/tls/connect_private_key",
                 str(cert_from / role / f"{role}.key"))
    return conf


@pytest.fixture
def fleet(certs):
    """A secured router and a function opening a session of a role."""
    port = free_port()
    with contextlib.ExitStack() as stack:
        stack.enter_context(zenoh.open(router_config(certs, port)))

        def session(role):
            return stack.enter_context(zenoh.open(client_config(certs, role, port)))

        yield session, port


def fails_to_open(conf: zenoh.Config) -> bool:
    try:
        session = zenoh.open(conf)
    except zenoh.ZError:
        return True
    session.close()
    return False


def collector(session, key):
    got, lock = [], threading.Lock()

    def on(sample):
        with lock:
            got.append(sample.payload.to_bytes())

    session.declare_subscriber(key, on)
    return got


def fake_response(robot="r1") -> bytes:
    return encode(Response(robot=robot, seq=999, stamp=1.0, model="asnn", preset="x", u=1.0,
                           out=1.0, spikes=9, spike_rate=99.0, collision=True, targets=[],
                           worker="intruder", latency_ms=0.0, dropped=0))


def test_each_role_does_its_job_and_nothing_else(fleet):
    session, _ = fleet
    worker_session, camera, dashboard, alerts = (session(r) for r in
                                                 ("worker", "camera-r1", "dashboard", "alerts"))
    core = WorkerCore(worker_id="secure-w1", idle_timeout=600)
    with Worker(worker_session, core, stats_every=0):
        responses = Responses(dashboard)
        warnings = []
        listener = WarningListener(alerts, warnings.append)
        wait_for(lambda: live_workers(dashboard) == ["secure-w1"], what="the worker's token")

        # the allowed path: camera -> worker -> dashboard and alerts
        scene = make_scene("looming")
        publisher = camera.declare_publisher(keys.frame_key("r1"))
        wait_for(lambda: publisher.matching_status.matching, what="the camera to see the worker")
        for seq, image in enumerate(scene.frames):
            publisher.put(encode(Frame.from_image(image, seq=seq, stamp=seq * 0.05)))
            wait_for(lambda: any(r.seq == seq for r in responses.since(0, "r1")),
                     what=f"response {seq}")
        sent = [r for r in responses.since(0, "r1") if r.collision]
        assert sent
        wait_for(lambda: len(warnings) >= len(sent), what="the warnings at the alerts client")
        status = query_status(dashboard)
        assert status["secure-w1"]["stats"]["processed"] == len(scene.frames)

        # (the collectors are on other sessions: a session delivers its own puts locally)
        # a camera cannot publish a warning or a response, nor read the responses
        camera_reads = collector(session("camera-r1"), keys.responses())
        dashboard_warnings = collector(alerts, keys.warnings())
        camera.put(keys.warning_key("r1"), fake_response())
        camera.put(keys.response_key("r1"), fake_response())
        # a dashboard cannot inject frames, nor read them
        dashboard_frames = collector(session("dashboard"), keys.frames())
        injected = encode(Frame.from_image(scene.frames[30], seq=0, stamp=0.0))
        dashboard.put(keys.frame_key("r9"), injected)
        alerts.put(keys.frame_key("r8"), injected)
        dashboard.put(keys.warning_key("r1"), fake_response())
        # a worker's status is answered, but a dashboard cannot pose as a worker
        dashboard.liveliness().declare_token(keys.worker_token_key("fake"))
        time.sleep(QUIET)
        publisher.put(encode(Frame.from_image(scene.frames[0], seq=1000, stamp=100.0)))
        wait_for(lambda: any(r.seq == 1000 for r in responses.since(0, "r1")),
                 what="a frame after the attempts")
        time.sleep(0.3)

        assert camera_reads == [] and dashboard_frames == [] and dashboard_warnings == []
        assert all(r.worker == "secure-w1" for r in responses.since(0))
        assert all(w.worker == "secure-w1" for w in warnings)
        assert core.robots() == ["r1"]  # r9 and r8 never reached the worker
        assert core.stats()["received"] == len(scene.frames) + 1
        assert live_workers(dashboard) == ["secure-w1"]
        # another worker sees this one (a session's liveliness query does not reliably return
        # the session's own tokens: seen once in ~30 runs, so ask from a second session)
        assert live_workers(session("worker")) == ["secure-w1"]
        listener.close()
        # a late alerts client still gets the cached last warning through the access control
        late = []
        with WarningListener(session("alerts"), late.append):
            wait_for(lambda: late, what="the cached warning for a late subscriber")
        assert (late[0].robot, late[0].seq) == ("r1", sent[-1].seq)


def test_the_worker_identity_may_ask_the_workers_status_for_its_health_check(fleet):
    """A worker's container checks its health with its own credentials (``asnn status --local``
    in deploy/compose.secure.yml): the worker identity may query the status queryables; a
    camera still may not."""
    session, _ = fleet
    core = WorkerCore(worker_id="secure-w1", idle_timeout=600)
    with Worker(session("worker"), core, stats_every=0):
        wait_for(lambda: live_workers(session("dashboard")) == ["secure-w1"],
                 what="the worker's token")
        assert list(query_status(session("worker"))) == ["secure-w1"]
        assert query_status(session("camera-r1"), timeout=1.0) == {}


def test_the_foxglove_identity_only_views(fleet):
    """The Foxglove live server's identity (deploy/compose.secure.yml) reads what dashboards
    read, and cannot feed the fleet."""
    session, _ = fleet
    worker, foxglove, camera = session("worker"), session("foxglove"), session("camera-r1")
    seen = collector(foxglove, keys.responses())
    frames = collector(session("worker"), keys.frames())
    time.sleep(0.3)  # the subscriptions reach the router
    worker.put(keys.response_key("r1"), fake_response())
    wait_for(lambda: seen, what="a response at the foxglove identity")
    image = make_scene("looming").frames[0]
    foxglove.put(keys.frame_key("r1"), encode(Frame.from_image(image, seq=1, stamp=0.0)))
    foxglove.put(keys.warning_key("r1"), fake_response())
    camera.put(keys.frame_key("r1"), encode(Frame.from_image(image, seq=2, stamp=0.0)))
    wait_for(lambda: frames, what="the camera's frame (the control)")
    time.sleep(QUIET)
    assert [decode_frame(f).seq for f in frames] == [2] and len(seen) == 1


def test_wrong_or_unknown_credentials_cannot_connect(fleet, certs):
    _, port = fleet
    assert fails_to_open(client_config(certs, "camera-r1", port, password="not-the-password"))
    conf = client_config(certs, "camera-r1", port)
    set_json(conf, "transport/auth/usrpwd/user", "mallory")
    assert fails_to_open(conf)
    conf = client_config(certs, "camera-r1", port)
    set_json(conf, "transport/auth/usrpwd", {"user": None, "password": None})
    assert fails_to_open(conf)
    assert not fails_to_open(client_config(certs, "camera-r1", port))  # the control


def test_a_router_with_an_untrusted_certificate_is_refused(fleet, certs, rogue):
    _, port = fleet
    assert fails_to_open(client_config(certs, "alerts", port, ca=rogue / "ca.pem"))


def test_plain_tcp_is_not_served(certs):
    port = free_port()
    conf = router_config(certs, port)
    set_json(conf, "listen/endpoints", [f"tls/127.0.0.1:{port}", f"tcp/127.0.0.1:{free_port()}"])
    # the router only speaks TLS: a tcp listener is refused outright
    assert fails_to_open(conf)


def test_mtls_refuses_clients_without_a_trusted_certificate(certs, rogue):
    port = free_port()
    with zenoh.open(router_config(certs, port)):
        assert not fails_to_open(client_config(certs, "dashboard", port))
        assert fails_to_open(client_config(certs, "dashboard", port, cert_from=rogue))
        conf = client_config(certs, "dashboard", port)
        set_json(conf, "transport/link/tls/enable_mtls", False)  # no client certificate
        assert fails_to_open(conf)


def test_a_refused_connection_says_why(certs, rogue):
    """Zenoh reports every failure to connect alike ("Unable to connect to any of ..."); the
    commands say which step failed: nothing listening, the router's certificate not trusted,
    the client's refused or missing, or the user and password after TLS worked."""
    from cli.session import open_session
    from service.config import ConfigError

    def why(conf):
        with pytest.raises(ConfigError) as caught:
            open_session(conf)
        assert "Unable to connect" in str(caught.value)
        return str(caught.value)

    port = free_port()
    with zenoh.open(router_config(certs, port)):
        assert "certificate is not trusted by " + str(rogue / "ca.pem") in why(
            client_config(certs, "alerts", port, ca=rogue / "ca.pem"))
        assert "refused this client's certificate " + str(rogue / "dashboard" / "dashboard.pem") \
            in why(client_config(certs, "dashboard", port, cert_from=rogue))
        conf = client_config(certs, "dashboard", port)
        for key in ("connect_certificate", "connect_private_key"):
            set_json(conf, f"transport/link/tls/{key}", None)
        assert "requires a client certificate" in why(conf)
        assert "check the user 'camera-r1' and its password" in why(
            client_config(certs, "camera-r1", port, password="not-the-password"))
        conf = client_config(certs, "alerts", port)
        set_json(conf, "connect/endpoints", [f"tcp/127.0.0.1:{port}"])
        assert "does the router speak TLS" in why(conf)
        conf = client_config(certs, "alerts", port)
        set_json(conf, "transport/link/tls/root_ca_certificate", str(certs / "absent.pem"))
        assert f"root_ca_certificate {certs / 'absent.pem'} cannot be read" in why(conf)
        open_session(client_config(certs, "alerts", port)).close()  # the control
    assert "nothing accepts connections at 127.0.0.1" in why(client_config(certs, "alerts", port))


def _reissue(certs: Path, folder: str, days: int) -> None:
    """Sign ``folder``'s certificate again with its key, valid for ``days`` (-1: expired)."""
    name = certs / folder / folder
    csr = name.with_suffix(".csr")
    subprocess.run(["openssl", "req", "-new", "-key", f"{name}.key", "-subj", f"/CN={folder}",
                    "-out", str(csr)], check=True, capture_output=True, timeout=60)
    extensions = certs / "ext.cnf"
    extensions.write_text("subjectAltName=DNS:localhost,IP:127.0.0.1,DNS:router\n"
                          "extendedKeyUsage=serverAuth,clientAuth\n")
    subprocess.run(["openssl", "x509", "-req", "-in", str(csr), "-CA", str(certs / "ca.pem"),
                    "-CAkey", str(certs / "ca.key"), "-days", str(days), "-extfile",
                    str(extensions), "-out", f"{name}.pem"],
                   check=True, capture_output=True, timeout=60)


def test_a_refused_certificate_says_what_would_fix_it(certs, tmp_path):
    """An expired certificate, or one that does not name the address connected to, is not
    fixed by another CA: the message says what is wrong with it (a deployment trial)."""
    from cli.session import open_session
    from service.config import ConfigError

    def why(conf):
        with pytest.raises(ConfigError) as caught:
            open_session(conf)
        return str(caught.value)

    expired = tmp_path / "expired"
    shutil.copytree(certs, expired)
    for folder in ("router", "alerts"):
        _reissue(expired, folder, -1)
    # the router's config names its files in ``certs``: point it at the copy's
    port = free_port()
    conf = router_config(certs, port)
    for key in ("listen_certificate", "listen_private_key"):
        set_json(conf, f"transport/link/tls/{key}",
                 str(expired / "router" / f"router.{'pem' if 'cert' in key else 'key'}"))
    with zenoh.open(conf):
        message = why(client_config(certs, "alerts", port))
        assert "out of its validity (certificate has expired)" in message, message
        assert "gen-dev-certs.sh again" in message
    port = free_port()
    with zenoh.open(router_config(certs, port)):
        message = why(client_config(certs, "alerts", port, cert_from=expired))
        assert "it has expired" in message and "gen-dev-certs.sh again" in message, message
        # the router's certificate names 127.0.0.1, not 127.0.0.2 (the same loopback)
    port = free_port()
    conf = router_config(certs, port)
    set_json(conf, "listen/endpoints", [f"tls/127.0.0.2:{port}"])
    with zenoh.open(conf):
        client = client_config(certs, "alerts", port)
        set_json(client, "connect/endpoints", [f"tls/127.0.0.2:{port}"])
        message = why(client)
        assert "does not name 127.0.0.2 (IP address mismatch" in message, message
        assert "gen-dev-certs.sh [--robots ...] [OUT_DIR] 127.0.0.2" in message


def test_a_router_that_cannot_read_a_file_names_the_file_and_its_setting(certs, tmp_path,
                                                                         capsys):
    """An operations trial: Zenoh's error names neither the file nor the setting ('No such
    file or directory (os error 2)' for a missing CA)."""
    from cli.main import main

    router = tmp_path / "router"
    shutil.copytree(certs / "router", router)
    config = tmp_path / "router.json5"
    config.write_text((router / "router.json5").read_text().replace(
        str(certs / "router"), str(router)))
    for name, setting in (("ca.pem", "transport/link/tls/root_ca_certificate"),
                          ("router.key", "transport/link/tls/listen_private_key"),
                          ("credentials.txt", "transport/auth/usrpwd/dictionary_file")):
        (router / name).rename(router / f"{name}.away")
        assert main(["router", "--config", str(config), "--listen",
                     f"tls/127.0.0.1:{free_port()}"]) == 2
        err = capsys.readouterr().err
        assert f"({setting} {router / name}: No such file or directory)" in err, err
        (router / f"{name}.away").rename(router / name)


def test_endpoints_are_split_for_the_check():
    from service.diagnosis import split_endpoint

    assert split_endpoint("tls/routerhost.example:7447") == ("tls", "routerhost.example", 7447)
    assert split_endpoint("tcp/[::1]:7447#iface=lo") == ("tcp", "::1", 7447)
    assert split_endpoint("tcp/10.0.0.1:7447?prio=1-7") == ("tcp", "10.0.0.1", 7447)
    for endpoint in ("udp/10.0.0.1:7447", "tcp/10.0.0.1", "unixsock-stream/tmp/z", "tls/"):
        assert split_endpoint(endpoint) is None


def test_no_secret_is_committed():
    if shutil.which("git") is None:  # a source tarball's tests, on a machine without git
        pytest.skip("no git here")
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    if tracked.returncode != 0:
        pytest.skip("not a git checkout")
    for name in tracked.stdout.split():
        assert not name.endswith((".key", ".pem", ".crt", "credentials.txt")), name


IDENTITIES = ("worker", "dashboard", "alerts", "foxglove", *(f"camera-{r}" for r in ROBOTS))


def test_each_identity_s_folder_holds_its_own_secrets_only(certs):
    """Each folder is mounted alone into its service's container: a viewer's container must not
    hold the worker's key, the CA's key or the router's password dictionary."""
    assert (certs / "ca.key").is_file()
    for name in IDENTITIES:
        assert sorted(p.name for p in (certs / name).iterdir()) == sorted(
            ["ca.pem", f"{name}.pem", f"{name}.key", f"{name}.json5"])
    assert sorted(p.name for p in (certs / "router").iterdir()) == sorted(
        ["ca.pem", "router.pem", "router.key", "credentials.txt", "router.json5"])
    assert certs.stat().st_mode & 0o077 == 0


def test_secrets_are_readable_by_their_owner_only(certs):
    """Keys and passwords are mode 600 (OUT_DIR's 700 alone would not keep them from a user
    given the folder, e.g. mounted into a container); the certificates are public."""
    def mode(path: Path) -> int:
        return stat.S_IMODE(path.stat().st_mode)

    secret = [certs / "ca.key", certs / "router" / "router.key",
              certs / "router" / "credentials.txt"]
    public = [certs / "ca.pem", certs / "router" / "router.pem", certs / "router" / "ca.pem",
              certs / "router" / "router.json5"]
    for name in IDENTITIES:
        assert "password" in (certs / name / f"{name}.json5").read_text()  # hence secret
        secret += [certs / name / f"{name}.key", certs / name / f"{name}.json5"]
        public += [certs / name / f"{name}.pem", certs / name / "ca.pem"]
        assert mode(certs / name) == 0o755
    assert {str(p): mode(p) for p in secret} == {str(p): 0o600 for p in secret}
    assert {str(p): mode(p) for p in public} == {str(p): 0o644 for p in public}


def test_running_the_script_again_keeps_the_ca_and_the_identities(tmp_path):
    """Adding a robot must not invalidate the credentials already deployed."""
    out = tmp_path / "secrets"

    def run(robots, *hosts):
        return subprocess.run(["bash", str(SCRIPT), "--robots", robots, str(out), *hosts],
                              check=True, capture_output=True, text=True, timeout=180,
                              env={**os.environ, "ASNN_CERT_DAYS": "30"})

    run("r1,r1")  # a repeated id is one identity (else the router's rule ids repeat)
    before = {name: (out / name / f"{name}.json5").read_text()
              for name in ("worker", "camera-r1")}
    ca = (out / "ca.pem").read_text()
    run("r1,r2", "routerhost")  # certificates of 30 days are not "expiring" at once
    assert (out / "ca.pem").read_text() == ca
    assert {name: (out / name / f"{name}.json5").read_text() for name in before} == before
    users = [line.split(":")[0] for line in
             (out / "router" / "credentials.txt").read_text().splitlines()]
    assert users == ["worker", "dashboard", "alerts", "foxglove", "camera-r1", "camera-r2"]
    # the new robot's camera may connect to a router that names routerhost
    port = free_port()
    with zenoh.open(router_config(out, port)):
        assert not fails_to_open(client_config(out, "camera-r2", port))
        assert not fails_to_open(client_config(out, "worker", port))
    # a robot left out loses its access, and the script says its folder is left over; a HOST
    # left out is no longer in the router's certificate, and the script says so too (an
    # operations trial: clients reaching the router by that name were refused unwarned)
    said = run("r1").stderr
    assert "camera-r2/ is no longer an identity" in said
    assert "the router's new certificate no longer names DNS:routerhost (the old one" in said
    assert "no longer names" not in run("r1").stderr  # and only where it did before
    # a renewed identity keeps its password: its new certificate and key alone are installed
    (out / "worker" / "worker.pem").unlink()
    assert "(issued: worker;" in run("r1").stderr
    assert (out / "worker" / "worker.json5").read_text() == before["worker"]
    # one whose folder was deleted (to revoke a leaked copy) gets a new password: the old
    # certificate is still the CA's, and only the password locks the copy out
    shutil.rmtree(out / "camera-r1")
    run("r1")
    assert (out / "camera-r1" / "camera-r1.json5").read_text() != before["camera-r1"]
    port = free_port()
    with zenoh.open(router_config(out, port)):
        assert fails_to_open(client_config(out, "camera-r2", port))
        assert not fails_to_open(client_config(out, "camera-r1", port))


def test_the_secure_compose_override_parses_and_names_existing_files():
    yaml = pytest.importorskip("ruamel.yaml")
    from cli.main import build_parser

    loader = yaml.YAML(typ="safe")
    # Compose's merge tag: the override's list replaces the base file's instead of adding to it
    loader.constructor.add_constructor(
        "!override", lambda constructor, node: ("override", constructor.construct_sequence(node)))
    override = loader.load((ROOT / "deploy" / "compose.secure.yml").read_text())
    parser = build_parser()
    for name, service in override["services"].items():
        if name == "router":
            assert service["command"] == ["--config", "/etc/asnn/secrets/router.json5"]
            assert service["volumes"] == ["./deploy/secrets/router:/etc/asnn/secrets:ro"]
            continue
        args = parser.parse_args(service["command"])
        identity = f"camera-{args.robot}" if name == "camera" else name
        # as the owner of the secrets, whose keys only the owner may read (mode 600)
        assert service["user"] == "${ASNN_UID:?the uid owning deploy/secrets (id -u)}:" \
                                  "${ASNN_GID:?its gid (id -g)}"
        assert args.connect == ["tls/router:7447"]
        assert args.config == f"/etc/asnn/secrets/{identity}.json5"
        # its own folder only: never the CA's key, another identity's or the passwords
        assert service["volumes"] == [f"./deploy/secrets/{identity}:/etc/asnn/secrets:ro"]
        if name in ("dashboard", "foxglove"):  # no authentication of their own: loopback only
            kind, ports = service["ports"]
            assert kind == "override" and all(p.startswith("127.0.0.1:") for p in ports)
    for name in ("router.json5", "client.json5"):
        conf = zenoh.Config.from_file(str(ROOT / "deploy" / "zenoh" / name))
        assert json.loads(conf.get_json("transport/link/tx/lease")) == 1000


def frames_reaching_the_worker(session, worker_session, attempts):
    """The seqs of the frames put by ``session``, the i-th with seq i on the key of robot
    ``attempts[i]``, that a subscriber on the worker's session receives (the worker identity
    may subscribe to every frame)."""
    got = collector(worker_session, keys.frames())
    image = make_scene("looming").frames[0]
    for seq, robot in enumerate(attempts):
        session.put(keys.frame_key(robot), encode(Frame.from_image(image, seq=seq, stamp=0.0)))
    time.sleep(QUIET)
    return [decode_frame(payload).seq for payload in got]


def test_a_camera_publishes_only_its_own_robots_frames(fleet):
    """Issue 13 (5, 6): any camera credential could publish frames for any robot id."""
    session, _ = fleet
    worker_session = session("worker")
    r1 = session("camera-r1")
    # seq 0 and 2 on r1's key (its own), seq 1 and 3 on r2's and another robot's
    got = frames_reaching_the_worker(r1, worker_session, ["r1", "r2", "r1", "r9"])
    assert sorted(got) == [0, 2]
    r2 = session("camera-r2")
    assert frames_reaching_the_worker(r2, worker_session, ["r1", "r2"]) == [1]


def test_a_password_is_bound_to_its_certificate(fleet, certs):
    """robot A's certificate with robot B's user and password: Zenoh admits the session (its
    authentication checks each on its own) but no subject matches both, so it may do nothing."""
    session, port = fleet
    worker_session = session("worker")
    password = client_config(certs, "camera-r2", port).get_json("transport/auth/usrpwd/password")
    conf = client_config(certs, "camera-r1", port, password=json.loads(password))
    set_json(conf, "transport/auth/usrpwd/user", "camera-r2")
    try:
        mixed = zenoh.open(conf)
    except zenoh.ZError:
        return  # refused outright: bound all the more
    with mixed:
        assert frames_reaching_the_worker(mixed, worker_session, ["r1", "r2"]) == []


def test_the_template_admits_no_camera_until_cameras_are_generated():
    conf = zenoh.Config.from_file(str(ROUTER))
    subjects = json.loads(conf.get_json("access_control/subjects"))
    assert all(s["usernames"] == s["cert_common_names"] for s in subjects)
    assert not any(s["id"].startswith("camera") for s in subjects)
    assert json.loads(conf.get_json("transport/link/tls/enable_mtls")) is True


def test_the_generator_refuses_bad_robot_ids(tmp_path):
    out = subprocess.run(["bash", str(SCRIPT), "--robots", "r1,bad/id", str(tmp_path / "s")],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "invalid robot id" in out.stderr


def test_the_generator_refuses_bad_hosts_and_days_before_writing_anything(tmp_path):
    # each exited 1 without a word (openssl's errors were thrown away), and a bad host left a
    # half-made folder; a comma would have added names of its own to the router's certificate
    cases = [((str(tmp_path / "a"), "bad,host"), {}, "invalid host 'bad,host'"),
             ((str(tmp_path / "b"), "two words"), {}, "invalid host 'two words'"),
             ((str(tmp_path / "e"), "999.1.1.1"), {}, "invalid host '999.1.1.1'"),
             ((str(tmp_path / "f"), ":"), {}, "invalid host ':'"),
             ((str(tmp_path / "c"),), {"ASNN_CERT_DAYS": "0"}, "ASNN_CERT_DAYS must be"),
             ((str(tmp_path / "d"),), {"ASNN_CERT_DAYS": "abc"}, "ASNN_CERT_DAYS must be"),
             # a path the configs' JSON5 strings cannot hold as it is
             ((str(tmp_path / 'q"uote'),), {}, "cannot hold a quote"),
             ((str(tmp_path / "g"),), {"ASNN_SECRETS_PATH": "/etc/a\\b"}, "a backslash"),
             ((str(tmp_path / "h"),), {"ASNN_SECRETS_PATH": "/etc/a\nb"}, "a line break"),
             ((str(tmp_path / "i\nj"),), {}, "a line break")]
    for args, env, said in cases:
        out = subprocess.run(["bash", str(SCRIPT), *args], capture_output=True, text=True,
                             timeout=60, env={**os.environ, **env})
        assert out.returncode == 2 and said in out.stderr, out.stderr
        assert not Path(args[0]).exists()
    # a relative OUT_DIR is named by its whole path, the working directory's quote with it
    quoted = tmp_path / 'w"d'
    quoted.mkdir()
    out = subprocess.run(["bash", str(SCRIPT), "secrets"], capture_output=True, text=True,
                         timeout=60, cwd=quoted)
    assert out.returncode == 2 and "cannot hold a quote" in out.stderr, out.stderr
    assert not (quoted / "secrets").exists()
    # where OUT_DIR is whole, the working directory is not in the configs: it may hold one
    subprocess.run(["bash", str(SCRIPT), str(tmp_path / "whole")], check=True,
                   capture_output=True, timeout=120, cwd=quoted)
    assert (tmp_path / "whole" / "router" / "router.json5").exists()


def test_an_ampersand_in_the_secrets_path_is_itself_in_the_router_s_config(tmp_path):
    """A security review: bash 5.2 read the & of ASNN_SECRETS_PATH=/srv/a&b as the text it
    replaced, and the router's config named /srv/a/etc/asnn/secretsb/router.pem."""
    out = tmp_path / "R&D"
    subprocess.run(["bash", str(SCRIPT), str(out)], check=True, capture_output=True, timeout=120,
                   env={**os.environ, "ASNN_SECRETS_PATH": "/srv/a&b"})
    config = (out / "router" / "router.json5").read_text()
    assert 'listen_certificate: "/srv/a&b/router.pem"' in config
    assert "/etc/asnn/secrets" not in config
    subprocess.run(["bash", str(SCRIPT), str(out)], check=True, capture_output=True, timeout=120)
    assert f'"{out}/router/router.pem"' in (out / "router" / "router.json5").read_text()


def test_the_folder_written_to_is_private_whatever_the_path_to_it(tmp_path):
    """A review: with a link/.. in OUT_DIR, mkdir and chmod resolved it through the link and cd
    did not, so the CA key and passwords went into a folder left at mode 755."""
    (tmp_path / "other" / "dir").mkdir(parents=True)
    (tmp_path / "work" / "secrets").mkdir(parents=True, mode=0o755)
    (tmp_path / "work" / "link").symlink_to("../other/dir")
    subprocess.run(["bash", str(SCRIPT), "link/../secrets"], cwd=tmp_path / "work", check=True,
                   capture_output=True, timeout=120)
    written = tmp_path / "work" / "secrets"
    assert (written / "ca.key").exists() and written.stat().st_mode & 0o777 == 0o700


def test_the_generator_names_an_ipv6_host_and_says_why_openssl_failed(tmp_path):
    out = tmp_path / "s"
    subprocess.run(["bash", str(SCRIPT), str(out), "[fd00::2]", "routerhost.example"],
                   check=True, capture_output=True, timeout=180)
    names = subprocess.run(["openssl", "x509", "-in", str(out / "router" / "router.pem"),
                            "-noout", "-ext", "subjectAltName"],
                           check=True, capture_output=True, text=True).stdout
    assert "IP Address:FD00:0:0:0:0:0:0:2" in names and "DNS:routerhost.example" in names
    (out / "ca.key").write_text("not a key\n")
    failed = subprocess.run(["bash", str(SCRIPT), str(out)], capture_output=True, text=True,
                            timeout=180)
    assert failed.returncode == 1
    assert "openssl x509 failed" in failed.stderr and "CA private key" in failed.stderr


def test_the_fleet_keys_pass_the_access_control_for_their_owners_only(fleet):
    """Issue 14's keys: a camera announces its own robot only; workers claim the robots they
    serve and see each other's claims and the cameras' announcements; nobody else may claim.
    Two workers then share the announced robots, each receiving its own robots' frames."""
    from service.camera import Source, publish_frames
    from service.ownership import owner
    from service.worker import announced_cameras, fleet_claims

    session, _ = fleet
    watcher = session("worker")
    camera, dashboard = session("camera-r1"), session("dashboard")
    tokens = [camera.liveliness().declare_token(keys.camera_token_key("r1")),
              camera.liveliness().declare_token(keys.camera_token_key("r2")),  # not its robot
              camera.liveliness().declare_token(keys.claim_key("w9", "r1")),
              dashboard.liveliness().declare_token(keys.claim_key("w9", "r2"))]
    time.sleep(QUIET)
    assert announced_cameras(watcher) == ["r1"] and fleet_claims(watcher) == []
    for token in tokens:
        token.undeclare()

    scene = make_scene("looming", stop=30, frames=40)
    cores = [WorkerCore(worker_id=w, idle_timeout=600) for w in ("secure-w1", "secure-w2")]
    with Worker(session("worker"), cores[0], stats_every=0), \
            Worker(session("worker"), cores[1], stats_every=0, scan_interval=0):
        responses = Responses(dashboard)
        wait_for(lambda: live_workers(dashboard) == ["secure-w1", "secure-w2"],
                 what="both workers")
        cameras = [threading.Thread(target=publish_frames, kwargs=dict(
            session=session(f"camera-{r}"), robot=r, wait=30.0, fps=40.0, preview_hz=0,
            source=Source("looming", 20.0, False, lambda: iter(scene.frames))))
            for r in ("r1", "r2")]
        for thread in cameras:
            thread.start()
        for thread in cameras:
            thread.join(timeout=60)
        wait_for(lambda: {r.robot for r in responses.since(0) if r.seq >= 35} == {"r1", "r2"},
                 what="both robots answered to the end")
        owners = {r: owner(r, ["secure-w1", "secure-w2"]) for r in ("r1", "r2")}
        assert all(r.worker == owners[r.robot] for r in responses.since(0))
        assert sorted(fleet_claims(watcher)) == sorted((w, r) for r, w in owners.items())
        for core in cores:
            assert set(core.robots()) == {r for r, w in owners.items() if w == core.worker_id}


def test_a_camera_hears_its_own_robots_refusals_only_and_cannot_send_any(fleet):
    """The refusal notices (docs/contract.md): the workers tell a robot's camera, and no other
    camera, why its frames are refused (dashboards hear them all); a camera cannot forge a
    notice for another robot."""
    from service.messages import Refusal

    session, _ = fleet
    worker, forger = session("worker"), session("camera-r2")
    # (the collectors are on other sessions: a session delivers its own puts locally)
    heard_r1 = collector(session("camera-r1"), keys.refusal_key("r1"))
    heard_r2 = collector(session("camera-r2"), "asnn/*/refused")
    dashboard = collector(session("dashboard"), keys.refusals())
    time.sleep(QUIET)  # the subscriptions reach the router
    notice = encode(Refusal(robot="r1", worker="w", reason="bad-size", detail="", count=1))
    worker.put(keys.refusal_key("r1"), notice)
    forger.put(keys.refusal_key("r1"), notice)
    wait_for(lambda: heard_r1, what="the worker's notice at r1's camera")
    time.sleep(QUIET)
    assert len(heard_r1) == 1 and heard_r2 == [] and len(dashboard) == 1


def test_every_documented_secured_compose_command_has_the_owner_s_ids():
    """The overlay's ``user:`` is ``${ASNN_UID:?...}:${ASNN_GID:?...}``, which compose resolves
    for every command given the file (``up``, ``ps``, ``logs``, ``down``): each place that shows
    one sets both first (inline, or exported earlier in the same file)."""
    root, shown = ROOT, 0
    for name in ("README.md", "docs/operations.md", "deploy/compose.secure.yml"):
        exported = False
        for line in (root / name).read_text().splitlines():
            if "export ASNN_UID=" in line and "ASNN_GID=" in line:
                exported = True
            if "docker compose" in line and "compose.secure.yml" in line:
                shown += 1
                assert exported or ("ASNN_UID=" in line and "ASNN_GID=" in line), (name, line)
    assert shown >= 3
    # and the overlay's own header says the other commands need them too
    header = (root / "deploy" / "compose.secure.yml").read_text()
    assert "every command with this file needs them" in header and "ps  # logs, down" in header


def test_every_file_the_router_cannot_read_is_named(certs, tmp_path):
    """A mutation probe: the trial moved one file away at a time, so naming the first alone,
    or leaving its TLS certificate out, passed it."""
    import zenoh

    from service.diagnosis import unreadable_files

    router = tmp_path / "router"
    shutil.copytree(certs / "router", router)
    config = tmp_path / "router.json5"
    config.write_text((router / "router.json5").read_text().replace(
        str(certs / "router"), str(router)))
    assert unreadable_files(zenoh.Config.from_file(str(config))) is None
    for name in ("router.pem", "router.key", "ca.pem", "credentials.txt"):
        (router / name).unlink()
    why = unreadable_files(zenoh.Config.from_file(str(config)))
    tls = "transport/link/tls/"
    assert why == "; ".join(
        f"{setting} {router / name}: No such file or directory" for setting, name in (
            (tls + "listen_certificate", "router.pem"), (tls + "listen_private_key", "router.key"),
            (tls + "root_ca_certificate", "ca.pem"),
            ("transport/auth/usrpwd/dictionary_file", "credentials.txt")))


def short_lived_certificate(path: Path, days: float, name: str = "alerts") -> Path:
    """A self-signed certificate (PEM) of ``name`` that ends ``days`` days from now (negative:
    ended), written to ``path``."""
    path.write_bytes(pem(certificate(days, name)[0]))
    return path


def test_a_certificate_that_ends_soon_or_has_ended_is_said_with_what_it_will_do(tmp_path):
    """A fleet operator's trial: a session outlives its certificate (the router checks it at
    the handshake only), so one that expired while the process ran locked it out at its next
    connection without a word beforehand, and a fleet issued together went dark together."""
    import base64

    from service.diagnosis import expiring_certificates

    soon = short_lived_certificate(tmp_path / "soon.pem", 10.2)
    ended = short_lived_certificate(tmp_path / "ended.pem", -1)
    later = short_lived_certificate(tmp_path / "later.pem", 200)
    conf = zenoh.Config()
    set_json(conf, "transport/link/tls/connect_certificate", str(soon))
    said = expiring_certificates(conf)
    assert said.startswith(f"connect_certificate {soon} expires on ")
    assert "in 10 days" in said and "gen-dev-certs.sh again" in said
    assert "the router refuses this client at its next connection" in said
    set_json(conf, "transport/link/tls/connect_certificate", str(later))
    assert expiring_certificates(conf) is None
    assert "connect_certificate" in expiring_certificates(conf, within_days=250)
    set_json(conf, "transport/link/tls/root_ca_certificate", str(ended))
    said = expiring_certificates(conf)
    assert said.startswith(f"root_ca_certificate {ended} expired on ") and ";" not in said
    router = zenoh.Config()  # a router's own certificate, given inline
    set_json(router, "transport/link/tls/listen_certificate_base64",
             base64.b64encode(soon.read_bytes()).decode())
    assert expiring_certificates(router).startswith("listen_certificate (inline) expires on ")
    # a trust bundle (a system's holds CAs long ended) by the CA of this process's own
    # certificate; without one, by its latest: it said "expired" of every client's bundle
    bundle = tmp_path / "bundle.pem"
    bundle.write_bytes(ended.read_bytes() + later.read_bytes())
    conf = zenoh.Config()
    set_json(conf, "transport/link/tls/root_ca_certificate", str(bundle))
    assert expiring_certificates(conf) is None
    set_json(conf, "transport/link/tls/connect_certificate", str(later))  # issued by "alerts"
    assert expiring_certificates(conf) is None
    issued = short_lived_certificate(tmp_path / "by-old.pem", 200, name="old-ca")
    old_ca = short_lived_certificate(tmp_path / "old-ca.pem", -1, name="old-ca")
    bundle.write_bytes(old_ca.read_bytes() + later.read_bytes())
    set_json(conf, "transport/link/tls/connect_certificate", str(issued))
    assert expiring_certificates(conf).startswith(f"root_ca_certificate {bundle} expired on ")
    # what cannot be read or parsed is not judged here: opening the session says so
    set_json(conf, "transport/link/tls/root_ca_certificate", str(tmp_path / "none.pem"))
    (tmp_path / "junk.pem").write_text("not a certificate")
    set_json(conf, "transport/link/tls/connect_certificate", str(tmp_path / "junk.pem"))
    assert expiring_certificates(conf) is None
    set_json(conf, "transport/link/tls/connect_certificate", str(soon))
    assert expiring_certificates(conf) is not None
    with pytest.MonkeyPatch.context() as patch:  # an environment made before the dependency
        patch.setitem(sys.modules, "cryptography", None)
        assert expiring_certificates(conf) is None



def test_the_certificate_check_on_the_watch_s_thread_leaves_other_threads_warnings_alone(
        tmp_path, monkeypatch):
    """A concurrency review: the certificate check (the router watch's thread, once a day)
    loaded the certificates inside warnings.catch_warnings, which swaps the process's filters:
    meanwhile every other thread's warnings were ignored. A bundle's odd old CA, of which
    cryptography warns at each load, is still not said."""
    import warnings

    from cryptography import x509
    from cryptography.utils import CryptographyDeprecationWarning

    from service.diagnosis import expiring_certificates

    load, inside, done = x509.load_pem_x509_certificates, threading.Event(), threading.Event()

    def odd_bundle(pem):  # cryptography warns at its caller's line, as of a serial number <= 0
        warnings.warn("Parsed a serial number which wasn't positive", CryptographyDeprecationWarning,
                      stacklevel=2)
        inside.set()
        done.wait(30)
        return load(pem)

    monkeypatch.setattr(x509, "load_pem_x509_certificates", odd_bundle)
    conf = zenoh.Config()
    set_json(conf, "transport/link/tls/connect_certificate",
             str(short_lived_certificate(tmp_path / "soon.pem", 10.2)))
    said = []
    check = threading.Thread(target=lambda: said.append(expiring_certificates(conf)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.filterwarnings("always", append=True)  # after the filters set before
        check.start()
        assert inside.wait(30)
        warnings.warn("this thread's own", UserWarning)
        done.set()
        check.join(30)
    assert [str(w.message) for w in caught] == ["this thread's own"]
    assert "expires on" in said[0]


def certificate(days: float, name: str, issuer=None):
    """A certificate (and its key) of ``name`` that ends ``days`` days from now, signed by
    ``issuer`` (a certificate and its key; None: itself)."""
    import datetime

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    signer, signer_key = issuer or (None, key)
    now = datetime.datetime.now(datetime.timezone.utc)
    built = (x509.CertificateBuilder().subject_name(subject)
             .issuer_name(subject if signer is None else signer.subject)
             .public_key(key.public_key()).serial_number(x509.random_serial_number())
             .not_valid_before(now - datetime.timedelta(days=400))
             .not_valid_after(now + datetime.timedelta(days=days))
             .sign(signer_key, hashes.SHA256()))
    return built, key


def pem(*certificates) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return b"".join(c.public_bytes(serialization.Encoding.PEM) for c in certificates)


def test_a_certificate_chain_ends_with_its_first_and_a_bundle_with_the_ca_of_ours(tmp_path):
    """A mutation probe: a chain whose intermediate ends first stops serving then; a bundle
    is judged by the CA that issued this process's certificate, an intermediate too, wherever
    it lies in a bundle of a system's size."""
    from service.diagnosis import expiring_certificates

    root = certificate(3000, "root")
    ending = certificate(10, "intermediate", issuer=root)  # its end comes first
    leaf = certificate(200, "alerts", issuer=ending)
    chain = tmp_path / "chain.pem"
    chain.write_bytes(pem(leaf[0], ending[0]))
    conf = zenoh.Config()
    set_json(conf, "transport/link/tls/connect_certificate", str(chain))
    assert "in 9 days" in expiring_certificates(conf)
    # the trust bundle: the intermediate that issued ours has ended, its root has not; and
    # other CAs (a system bundle's) before them
    ended = certificate(-1, "intermediate", issuer=root)
    own = certificate(200, "alerts", issuer=ended)
    chain.write_bytes(pem(own[0]))
    bundle = tmp_path / "bundle.pem"
    others = [certificate(3000, f"other-{k}")[0] for k in range(150)]
    bundle.write_bytes(pem(*others, root[0], ended[0]))
    assert bundle.stat().st_size > 64_000
    set_json(conf, "transport/link/tls/root_ca_certificate", str(bundle))
    said = expiring_certificates(conf)
    assert said is not None and said.startswith(f"root_ca_certificate {bundle} expired on ")


def test_the_router_and_a_client_say_at_start_that_their_certificates_end_soon(procs,
                                                                               tmp_path):
    """The development fleet issued for 20 days: the router and a client each log, at start,
    which of their certificates expire within 30 days."""
    env = {**os.environ, "ASNN_CERT_DAYS": "20"}
    subprocess.run(["bash", str(SCRIPT), str(tmp_path / "fleet")], check=True,
                   capture_output=True, timeout=180, env=env)
    fleet = tmp_path / "fleet"
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = procs("router", "--config", str(fleet / "router" / "router.json5"),
                   "--listen", endpoint)
    router.wait_line("listening on")
    router.wait_line("router: listen_certificate ")
    alerts = procs("alerts", "--config", str(fleet / "alerts" / "alerts.json5"),
                   "--connect", endpoint)
    alerts.wait_line("alerts: connect_certificate ")
    said = next(line for line in alerts.err if "connect_certificate" in line)
    assert "expires on " in said and "in 19 days 23 hours" in said, said
    time.sleep(1.2)  # more than two looks of the router's loop (every 0.5 s)
    assert alerts.stop() == 0 and router.stop() == 0
    # said at start, not at every look of its loop
    assert sum("router: listen_certificate " in line for line in router.err) == 1


def test_a_certificate_check_that_fails_does_not_stop_the_router(procs, tmp_path):
    """A mutation probe: the router's look at its certificates may fail (an old cryptography
    without their UTC ends, an odd certificate): it says so at debug level and serves on."""
    boot = tmp_path / "boot"
    boot.mkdir()
    (boot / "sitecustomize.py").write_text(
        "import service.diagnosis\n"
        "def failing(*args, **kwargs):\n"
        "    raise AttributeError('not_valid_after_utc')\n"
        "service.diagnosis.expiring_certificates = failing\n")
    path = os.pathsep.join(p for p in (str(boot), str(ROOT), os.environ.get("PYTHONPATH"))
                           if p)
    router = procs("router", "--listen", f"tcp/127.0.0.1:{free_port()}", "--log-level",
                   "debug", env={"PYTHONPATH": path})
    router.wait_line("certificate check failed")
    assert router.popen.poll() is None
    assert router.stop() == 0
