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
from tests.support.checkpoints import assert_refused_everywhere, set_first_weight  # noqa: E402
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
    "short text": (lambda d: _write(d / "text.pt", b"junk"), "not a torch checkpoint"),  # struct.error inside torch
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


# ----------------------------------------------------------------------------- hostile files
# Each is refused at load time, before any network is built (CorrespondenceNet is replaced by a
# function that fails the test if called), with one line naming the file, the entry and its value.
# The oversized ones declare sizes only: their state dicts stay the small network's (the count is
# checked from the sizes, before any tensor is read), so nothing large is ever allocated here.




HOSTILE = {
    # audit 1: every size within [1, 4096], the total ~137 billion parameters (~550 GB of float32)
    "oversized network": (lambda p: p["network"].update(width=4096, blocks=4096),
                          "its 'network' {'n_features': 14, 'width': 4096, 'blocks': 4096} declares 137,472,573,441 parameters"),
    "just over the cap": (lambda p: p["network"].update(width=2048, blocks=2), "more than the 16,777,216"),
    "shapes contradict the sizes": (lambda p: p["state_dict"].update({"input.weight": torch.zeros(2, 2)}),
                                    "state_dict['input.weight'] has shape (2, 2), the network needs (8, 14)"),
    "an extra tensor": (lambda p: p["state_dict"].update({"extra": torch.zeros(3)}), "unexpected 'extra'"),
    "a missing tensor": (lambda p: p["state_dict"].pop("head.bias"), "missing 'head.bias'"),
    "integer weights": (lambda p: p["state_dict"].update({"head.bias": torch.zeros(1, dtype=torch.int64)}),
                        "state_dict['head.bias'] must be a dense floating-point tensor, got torch.int64"),
    # audit 4: non-finite weights
    "a NaN weight": (set_first_weight("input.weight", float("nan")), "state_dict['input.weight'] holds 1 NaN or infinite value(s)"),
    "an infinite weight": (set_first_weight("head.bias", float("-inf")), "state_dict['head.bias'] holds 1 NaN or infinite value(s)"),
    "a float64 weight beyond float32": (
        lambda p: p["state_dict"].update({"head.bias": torch.full((1,), 1e300, dtype=torch.float64)}),
        "state_dict['head.bias'] holds 1 NaN or infinite value(s)"),
    # audit 3's one-shot side: every schema field's type
    "feature_names an int": (lambda p: p.update(feature_names=5), "its 'feature_names' must be a list of strings, got 5"),
    "feature_names not strings": (lambda p: p.update(feature_names=[1, 2]), "its 'feature_names' must be a list of strings, got [1, 2]"),
    "format_version a string": (lambda p: p.update(format_version="1"), "its 'format_version' is '1'"),
    "format_version from the future": (lambda p: p.update(format_version=2), "its 'format_version' is 2; this version reads format 1"),
    "layout version a string": (lambda p: p.update(feature_layout_version="1"), "its 'feature_layout_version' must be an integer, got '1'"),
    "n_features beside the names": (lambda p: p["network"].update(n_features=5), "its network n_features is 5, but its 'feature_names' lists 14"),
    "n_features missing": (lambda p: p["network"].pop("n_features"), "its 'network' entry lacks n_features"),
    "a float width": (lambda p: p["network"].update(width=8.0), "network width must be an integer in [1, 4096], got 8.0"),
    "a bool width": (lambda p: p["network"].update(width=True), "network width must be an integer in [1, 4096], got True"),
    "a state_dict list": (lambda p: p.update(state_dict=[1]), "its 'state_dict' must map parameter names to tensors, got list"),
    "a state_dict key an int": (lambda p: p["state_dict"].update({1: torch.zeros(1)}),
                                "its 'state_dict' must map parameter names to tensors, got 1: Tensor"),
    "config a list": (lambda p: p.update(config=[1]), "its 'config' entry must be a dict, got list"),
}


@pytest.fixture
def no_network_built(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError(f"a network was built for a hostile file: CorrespondenceNet{args}")
    monkeypatch.setattr(ckpt, "CorrespondenceNet", refuse)


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_one_shot_files_are_refused_before_any_network_is_built(tmp_path, case, capsys, no_network_built):
    import agents

    edit, what = HOSTILE[case]
    path = _variant(tmp_path, "hostile", edit)
    commands = {
        "vo": ["vo", "--agent", str(path), "--method", "msac", "--frames", "2", "--no-progress"],
        "evaluate": ["evaluate", "--agent", str(path)],
        "train": ["train", "--resume", str(path), "--no-progress"],
    }
    assert_refused_everywhere(path, what, (load_checkpoint, load_sampler, agents.load_sampler), commands, tmp_path,
                              capsys)


def test_network_sizes_give_the_shapes_and_count_of_the_network_they_build():
    from agents.network import correspondence_net_shapes
    from agents.network_size import correspondence_net_parameters

    for sizes in [(N_FEATURES, 8, 1), (N_FEATURES, 64, 3), (3, 5, 0), (25, 32, 2)]:
        state = CorrespondenceNet(*sizes).state_dict()
        assert {k: tuple(v.shape) for k, v in state.items()} == correspondence_net_shapes(*sizes)
        assert correspondence_net_parameters(*sizes) == sum(v.numel() for v in state.values())


@pytest.mark.parametrize("name", SHIPPED_SAMPLERS)
def test_the_shipped_networks_are_far_below_the_size_cap(name):
    from agents.network_size import correspondence_net_parameters

    with ckpt.shipped_checkpoint(name) as path:
        payload = torch.load(path, weights_only=True)
    count = correspondence_net_parameters(**payload["network"])
    assert count == sum(v.numel() for v in payload["state_dict"].values())
    assert 100 * count < ckpt.MAX_NETWORK_PARAMETERS
