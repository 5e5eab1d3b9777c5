"""docker-compose.yml and deploy/: checked as files (no Docker engine is needed)."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]
COMPOSE = ROOT / "docker-compose.yml"


def load_compose() -> dict:
    yaml = pytest.importorskip("ruamel.yaml")  # comes with check-jsonschema (dev extra)
    return yaml.YAML(typ="safe").load(COMPOSE.read_text())


def check_jsonschema() -> list[str]:
    exe = shutil.which("check-jsonschema")
    if exe:
        return [exe]
    pytest.importorskip("check_jsonschema")
    return [sys.executable, "-m", "check_jsonschema"]


def test_compose_file_passes_the_compose_spec_schema():
    result = subprocess.run([*check_jsonschema(), "--builtin-schema", "vendor.compose-spec",
                             str(COMPOSE)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


def test_every_asnn_service_command_parses_with_the_cli_parser():
    services = load_compose()["services"]
    parser = build_parser()
    commands = {}
    for name, service in services.items():
        if service["image"].startswith("eclipse/zenoh"):
            continue
        command = list(service["command"])
        if command[0] == "asnn":  # with or without the image's entrypoint spelled out
            command = command[1:]
        args = parser.parse_args(command)
        assert callable(args.func)
        commands[args.command] = args
    assert set(commands) == {"camera", "worker", "alerts", "dashboard", "foxglove"}
    assert commands["camera"].loop and commands["camera"].source.startswith("/")
    for args in commands.values():
        assert args.connect == ["tcp/router:7447"] and args.mode == "client"
        assert (ROOT / "deploy" / "zenoh" / Path(args.config).name).is_file()


def test_topology_has_the_official_router_and_the_service_image():
    services = load_compose()["services"]
    assert services["router"]["image"].split(":")[0] == "eclipse/zenoh"
    for name in ("camera", "worker", "alerts"):
        assert services[name]["build"]["dockerfile"] == "deploy/Dockerfile"
        assert "router" in services[name]["depends_on"]
    dockerfile = (ROOT / "deploy" / "Dockerfile").read_text()
    assert 'ENTRYPOINT ["asnn"]' in dockerfile
    assert "write_video" in dockerfile  # the camera's clip is generated, not committed
    assert "pip install '.[ros]'" in dockerfile  # asnn foxglove and bags need the ros extra


@pytest.mark.parametrize("name", ["router.json5", "client.json5"])
def test_zenoh_configs_load(name):
    config = zenoh.Config.from_file(str(ROOT / "deploy" / "zenoh" / name))
    assert config.get_json("mode") == f'"{name.split(".")[0]}"'
