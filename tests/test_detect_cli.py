"""``asnn detect``: the JSONL contract of CONTRACT.md, outputs and errors."""

import json
import subprocess
import sys

import pytest

from asnn.stimuli import make_scene, write_video
from cli.main import main

FIELDS = {"frame": int, "t": float, "u": float, "out": float, "spikes": int,
          "spike_rate": float, "collision": bool, "targets": list}
TARGET_FIELDS = {"x": float, "y": float, "direction": float, "energy": float, "pixels": int}
# the default (tracked) preset's optional fields, docs/contract.md
TRACKED_FIELDS = {"id": int, "expansion": float, "ttc": float, "offset": float,
                  "approaching": bool}


@pytest.fixture(scope="module")
def looming_video(tmp_path_factory):
    scene = make_scene("looming", size=(96, 96), start=5, stop=30)
    path = tmp_path_factory.mktemp("clips") / "looming.avi"  # MJPG: decodable everywhere
    write_video(scene.frames, path, fps=20.0)
    return path, scene


def test_jsonl_has_one_object_per_frame_with_the_contract_fields(looming_video, capsys):
    path, scene = looming_video
    assert main(["detect", str(path), "--jsonl", "-"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(scene.frames)
    records = [json.loads(line) for line in lines]
    for i, rec in enumerate(records):
        assert set(rec) == set(FIELDS)
        for key, kind in FIELDS.items():
            assert isinstance(rec[key], kind) or (kind is float and isinstance(rec[key], int)), key
        assert rec["frame"] == i and rec["t"] == pytest.approx(i / 20.0)
        for target in rec["targets"]:
            assert set(target) == set(TARGET_FIELDS) | set(TRACKED_FIELDS)
            for key, kind in {**TARGET_FIELDS, **TRACKED_FIELDS}.items():
                assert isinstance(target[key], kind) or (kind is float and isinstance(
                    target[key], int)), key
            assert 0 <= target["x"] < 96 and 0 <= target["y"] < 96
            # the default reports the approaching objects: growing, with a time to contact
            assert target["approaching"] and target["expansion"] > 0 and target["ttc"] > 0
    warned = [r for r in records if r["collision"]]
    assert warned and any(r["targets"] for r in warned)
    assert all(r["frame"] >= scene.onset_frame for r in warned)


def test_lgmd_models_are_selectable_and_report_no_targets(looming_video, capsys):
    path, scene = looming_video
    assert main(["detect", str(path), "--model", "lgmd2", "--jsonl", "-"]) == 0
    records = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert len(records) == len(scene.frames)
    assert all(r["targets"] == [] for r in records)


def test_annotate_and_plot_write_files(looming_video, tmp_path):
    path, scene = looming_video
    video, plot = tmp_path / "ann.mp4", tmp_path / "plot.png"
    assert main(["detect", str(path), "--annotate", str(video), "--plot", str(plot)]) == 0
    import cv2

    cap = cv2.VideoCapture(str(video))
    count = 0
    while cap.read()[0]:
        count += 1
    assert count == len(scene.frames)
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("content", [None, b"not a video at all\n" * 20])
def test_missing_or_undecodable_file_exits_2_with_one_line(tmp_path, content):
    path = tmp_path / "clip.mp4"
    if content is not None:
        path.write_bytes(content)
    proc = subprocess.run([sys.executable, "-m", "cli.main", "detect", str(path), "--jsonl", "-"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert len(proc.stderr.strip().splitlines()) == 1 and str(path) in proc.stderr
