"""Checkpoints run no code, and every unusable file is one line naming it (Python, evaluate, train --resume)."""

from __future__ import annotations

import io
import json
import os
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from agents import checkpoint as ckpt  # noqa: E402
from agents.checkpoint import (  # noqa: E402
    SHIPPED_SAMPLERS,
    CheckpointError,
    load_checkpoint,
    load_sampler,
    save_checkpoint,
)
from agents.network import CorrespondenceNet  # noqa: E402
from vo_gym_cli.main import main  # noqa: E402
from vo_gym.features import N_FEATURES  # noqa: E402
from tests.support.processes import run_python  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


class _Payload:
    """Unpickling this creates a file: the proof that a loader ran the file's code."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def _malicious(tmp_path: Path, legacy: bool) -> tuple[Path, Path]:
    marker = tmp_path / "pwned"
    path = tmp_path / ("legacy.pt" if legacy else "evil.pt")
    payload = {"feature_names": [], "network": {}, "x": _Payload(marker)}
    if legacy:
        torch.save(payload, path, _use_new_zipfile_serialization=False)
    else:
        torch.save(payload, path)
    assert not marker.exists()
    return path, marker


@pytest.mark.parametrize("legacy", [False, True])
def test_a_crafted_payload_runs_no_code(tmp_path, legacy):
    path, marker = _malicious(tmp_path, legacy)
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(path)
    assert not marker.exists()
    message = str(err.value)
    assert str(path) in message and "\n" not in message and "refused" in message
    # the same through the command line, which says so in one line and exits 2
    assert main(["evaluate", "--agent", str(path), "--out", str(tmp_path / "out")]) == 2
    assert not marker.exists()


def _good(tmp_path: Path) -> Path:
    return save_checkpoint(tmp_path / "good.pt", CorrespondenceNet(N_FEATURES, 8, 1), {"algo": "test"})


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _variant(tmp_path: Path, name: str, edit) -> Path:
    payload = torch.load(_good(tmp_path), weights_only=True)
    edit(payload)
    path = tmp_path / f"{name}.pt"
    torch.save(payload, path)
    return path


def _zip(path: Path) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("hello.txt", "not a checkpoint")
    return path


MALFORMED = {
    "random bytes": (lambda d: _write(d / "random.pt", np.random.default_rng(1).bytes(4096)), "not a torch checkpoint"),
    "truncated": (lambda d: _write(d / "trunc.pt", _half(_good(d).read_bytes())), "truncated or corrupt"),
    "empty": (lambda d: _write(d / "empty.pt", b""), "is empty"),
    "json renamed": (lambda d: _write(d / "json.pt", json.dumps({"network": {}}).encode()), "not a torch checkpoint"),
    "zip renamed": (lambda d: _zip(d / "zip.pt"), "zip archive"),
    "pickled list": (lambda d: _write(d / "list.pt", pickle.dumps([1, 2])), "not a torch checkpoint"),
    "missing layout": (lambda d: _variant(d, "nolayout", lambda p: p.pop("feature_layout_version")),
                       "missing key(s) feature_layout_version"),
    "missing weights": (lambda d: _variant(d, "noweights", lambda p: p.pop("state_dict")), "missing key(s) state_dict"),
    "changed width": (lambda d: _variant(d, "width", lambda p: p["network"].update(width=16)),
                      "weights do not fit the network"),
    "unknown network keyword": (lambda d: _variant(d, "kw", lambda p: p["network"].update(depth=3)),
                                "unknown network keyword(s) depth"),
    "bad network value": (lambda d: _variant(d, "val", lambda p: p["network"].update(width=-1)),
                          "network width must be an integer"),
    "not a dict": (lambda d: _write(d / "tensor.pt", _saved(torch.zeros(3))), "not a vo-gym sampler checkpoint"),
}


def _half(data: bytes) -> bytes:
    return data[: len(data) // 2]


def _saved(obj) -> bytes:
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_every_malformed_file_is_one_line_naming_it(tmp_path, case, capsys):
    make, what = MALFORMED[case]
    path = make(tmp_path)
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(path)
    message = str(err.value)
    assert str(path) in message and what in message and "\n" not in message, message
    assert isinstance(err.value, ValueError)
    # vo-gym evaluate --agent: one line, exit 2, nothing computed
    capsys.readouterr()
    assert main(["evaluate", "--agent", str(path), "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and what in lines[0], lines
    # vo-gym train --resume: the same
    assert main(["train", "--resume", str(path), "--out", str(tmp_path / "train"), "--no-progress"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and what in lines[0], lines


def test_a_missing_checkpoint_is_one_line(tmp_path, capsys):
    missing = tmp_path / "missing.pt"
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        load_checkpoint(missing)
    assert main(["train", "--resume", str(missing), "--out", str(tmp_path / "t")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(missing) in lines[0]


@pytest.mark.parametrize("name", SHIPPED_SAMPLERS)
def test_shipped_samplers_load_safely_by_name(name):
    policy = load_sampler(name)
    assert policy.name == name
    with ckpt.shipped_checkpoint(name) as path:
        torch.load(path, weights_only=True)  # data only


def test_unknown_sampler_name_lists_the_shipped_ones():
    with pytest.raises(ValueError, match="ngransac-supervised"):
        load_sampler("no-such-sampler")


def test_shipped_samplers_are_found_from_another_directory(tmp_path):
    """importlib.resources finds the package data wherever the process runs (no path relative to a clone)."""
    code = (
        "import agents; from agents.checkpoint import load_sampler, SHIPPED_SAMPLERS;"
        "print(' '.join(load_sampler(n).name for n in SHIPPED_SAMPLERS))"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    assert run_python(code, timeout=300, cwd=tmp_path, env=env).split() == list(SHIPPED_SAMPLERS)
