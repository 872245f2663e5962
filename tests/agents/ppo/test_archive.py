"""A PPO ``.zip`` runs no code, and every unusable zip is one line naming it (Python, evaluate, train --resume).

stable-baselines3 stores what JSON cannot hold as base64 cloudpickle under ":serialized:" in the
zip's ``data`` entry, and its own ``PPO.load`` unpickles it; :func:`agents.ppo.archive.load_ppo` never does.
"""

from __future__ import annotations

import base64
import io
import json
import os
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

from agents.checkpoint import CheckpointError, LearnedPolicy  # noqa: E402
from agents.evaluation.setup import resolve_agent  # noqa: E402
from agents.ppo import archive as ppo_archive  # noqa: E402
from agents.ppo.archive import load_ppo, load_ppo_actor, read_ppo_config  # noqa: E402
from agents.ppo.config import PPOConfig, build_model, make_training_env  # noqa: E402
from vo_gym import StereoVOEnv  # noqa: E402
from vo_gym_cli.main import main  # noqa: E402

CONFIG = dict(
    timesteps=64, n_envs=2, n_steps=32, batch_size=32, n_epochs=1, n_frames=4, n_correspondences=64, budget=8,
    width=8, blocks=1, critic_width=8, critic_hidden=8, eval_every=64, eval_frames=8, eval_n_correspondences=64,
    checkpoint_every=64,
)


class _Payload:
    """Unpickling this creates a file: the proof that a loader ran the file's code."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def _serialized(marker: Path) -> dict[str, str]:
    """An SB3 ":serialized:" entry whose unpickling creates ``marker``."""
    return {":serialized:": base64.b64encode(pickle.dumps(_Payload(marker))).decode()}


@pytest.fixture(scope="module")
def genuine(tmp_path_factory) -> Path:
    """A PPO zip saved by SB3 after one update (optimizer state and counters non-trivial)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        config = PPOConfig(**CONFIG)
        env = make_training_env(config)
        try:
            model = build_model(config, env)
            model.learn(total_timesteps=64, progress_bar=False)
            path = tmp_path_factory.mktemp("genuine") / "ppo.zip"
            model.save(str(path))
        finally:
            env.close()
    finally:
        torch.set_num_threads(before)
    return path


def _members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def _rewrite(source: Path, target: Path, edit) -> Path:
    """A copy of ``source`` with its members edited by ``edit(members)`` (a dict name -> bytes)."""
    members = _members(source)
    edit(members)
    with zipfile.ZipFile(target, "w") as archive:
        for name, raw in members.items():
            archive.writestr(name, raw)
    return target


def _edit_data(edit):
    def apply(members):
        data = json.loads(members["data"])
        edit(data)
        members["data"] = json.dumps(data).encode()
    return apply


def _saved(obj) -> bytes:
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


def _assert_refused_everywhere(path: Path, tmp_path: Path, capsys, what: str, marker: Path | None = None,
                               in_config: bool = True) -> None:
    """The Python loaders, ``vo-gym evaluate --agent`` and ``vo-gym train --algo ppo --resume``:
    one line naming the file and ``what``, exit code 2, and ``marker`` never created.
    ``in_config``: the defect is in what :func:`read_ppo_config` reads (not only in the weights)."""
    loaders = (load_ppo_actor, lambda p: load_ppo(p, env=None)) + ((read_ppo_config,) if in_config else ())
    for load in loaders:
        with pytest.raises(CheckpointError) as err:
            load(path)
        message = str(err.value)
        assert str(path) in message and what in message and "\n" not in message, message
        assert marker is None or not marker.exists()
    capsys.readouterr()
    assert main(["evaluate", "--agent", str(path), "--out", str(tmp_path / "eval")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and what in lines[0], lines
    assert marker is None or not marker.exists()
    assert main(["train", "--algo", "ppo", "--resume", str(path), "--out", str(tmp_path / "train"),
                 "--no-progress"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and what in lines[0], lines
    assert marker is None or not marker.exists()
    assert not (tmp_path / "train" / "ppo.zip").exists()  # nothing trained


def test_the_crafted_payload_is_live(tmp_path):
    """Control: SB3's own JSON decoding of the entry does run it (so the tests below prove something)."""
    from stable_baselines3.common.save_util import json_to_data

    marker = tmp_path / "ran"
    json_to_data(json.dumps({"policy_class": _serialized(marker)}))
    assert marker.exists()


@pytest.mark.parametrize("key", ["policy_class", "observation_space", "lr_schedule", "ep_info_buffer", "unknown_key"])
def test_a_serialized_entry_in_data_runs_no_code(genuine, tmp_path, key):
    marker = tmp_path / "pwned"
    path = _rewrite(genuine, tmp_path / "evil.zip", _edit_data(lambda d: d.update({key: _serialized(marker)})))
    # Nothing in ``data`` is decoded: the model loads (from its plain train_config) and the payload never runs.
    model = load_ppo(path)
    assert not marker.exists()
    assert model.num_timesteps == 64
    # what ``vo-gym evaluate --agent`` loads it through
    spec = resolve_agent(str(path))
    assert spec.kind == "checkpoint" and not marker.exists()


def test_a_serialized_train_config_is_refused_unrun(genuine, tmp_path, capsys):
    marker = tmp_path / "pwned"

    def edit(data):
        data["policy_kwargs"] = _serialized(marker)
    path = _rewrite(genuine, tmp_path / "evil.zip", _edit_data(edit))
    _assert_refused_everywhere(path, tmp_path, capsys, "no plain train_config", marker)

    def nested(data):
        data["policy_kwargs"]["train_config"] = _serialized(marker)
    path = _rewrite(genuine, tmp_path / "evil2.zip", _edit_data(nested))
    _assert_refused_everywhere(path, tmp_path, capsys, "no plain train_config", marker)


@pytest.mark.parametrize("member", ["policy.pth", "policy.optimizer.pth"])
@pytest.mark.parametrize("legacy", [False, True])
def test_a_pickle_payload_in_a_weights_member_runs_no_code(genuine, tmp_path, capsys, member, legacy):
    marker = tmp_path / "pwned"
    payload = pickle.dumps({"x": _Payload(marker)}, protocol=2) if legacy else _saved({"x": _Payload(marker)})
    assert not marker.exists()
    path = _rewrite(genuine, tmp_path / "evil.zip", lambda m: m.update({member: payload}))
    _assert_refused_everywhere(path, tmp_path, capsys, f"its {member!r} entry refused", marker, in_config=False)
    # a newer pickle protocol is refused before any global is looked at
    raw = pickle.dumps({"x": _Payload(marker)}, protocol=pickle.HIGHEST_PROTOCOL)
    path = _rewrite(genuine, tmp_path / "evil5.zip", lambda m: m.update({member: raw}))
    with pytest.raises(CheckpointError, match="nothing was run"):
        load_ppo_actor(path)
    assert not marker.exists()
    capsys.readouterr()
    assert main(["evaluate", "--agent", str(path), "--out", str(tmp_path / "eval")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and "nothing was run" in lines[0], lines


def _random(path: Path) -> Path:
    path.write_bytes(np.random.default_rng(0).bytes(4096))
    return path


def _truncated(genuine: Path, path: Path) -> Path:
    raw = genuine.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    return path


def _other_width(genuine: Path, path: Path, tmp_path: Path) -> Path:
    config = PPOConfig(**{**CONFIG, "width": 16})
    env = make_training_env(config)
    try:
        other = tmp_path / "other.zip"
        build_model(config, env).save(str(other))
    finally:
        env.close()
    state = _members(other)["policy.pth"]
    return _rewrite(genuine, path, lambda m: m.update({"policy.pth": state}))


MALFORMED = {
    "random bytes": (lambda g, p, t: _random(p), "is not a zip archive"),
    "empty": (lambda g, p, t: (p.write_bytes(b""), p)[1], "is empty"),
    "truncated": (lambda g, p, t: _truncated(g, p), "is not a zip archive"),
    "no data": (lambda g, p, t: _rewrite(g, p, lambda m: m.pop("data")), "no 'data' entry"),
    "bad json": (lambda g, p, t: _rewrite(g, p, lambda m: m.update(data=b"{not json")), "'data' entry is not JSON"),
    "not utf-8": (lambda g, p, t: _rewrite(g, p, lambda m: m.update(data=b"\xff\xfe")), "'data' entry is not JSON"),
    "json list": (lambda g, p, t: _rewrite(g, p, lambda m: m.update(data=b"[1, 2]")), "must be a JSON object"),
    "no policy": (lambda g, p, t: _rewrite(g, p, lambda m: m.pop("policy.pth")), "no 'policy.pth' entry"),
    "no optimizer": (lambda g, p, t: _rewrite(g, p, lambda m: m.pop("policy.optimizer.pth")), None),
    "policy not torch": (lambda g, p, t: _rewrite(g, p, lambda m: m.update({"policy.pth": b"garbage"})),
                         "'policy.pth' entry is not"),
    "policy a tensor": (lambda g, p, t: _rewrite(g, p, lambda m: m.update({"policy.pth": _saved(torch.zeros(3))})),
                        "must map parameter names to tensors"),
    "wrong shapes": (lambda g, p, t: _other_width(g, p, t), "policy weights do not fit"),
    "no train_config": (lambda g, p, t: _rewrite(g, p, _edit_data(lambda d: d["policy_kwargs"].pop("train_config"))),
                        "not a vo-gym PPO one"),
    "other layout": (lambda g, p, t: _rewrite(g, p, _edit_data(
        lambda d: d["policy_kwargs"]["train_config"].update(feature_layout_version=-7))), "another feature layout"),
    "bad config": (lambda g, p, t: _rewrite(g, p, _edit_data(
        lambda d: d["policy_kwargs"]["train_config"].update(width="wide"))), "not a valid PPO config"),
    "module env id": (lambda g, p, t: _rewrite(g, p, _edit_data(
        lambda d: d["policy_kwargs"]["train_config"].update(env_id="antigravity:Fly-v0"))),
        "not a registered environment"),
    "bad counter": (lambda g, p, t: _rewrite(g, p, _edit_data(lambda d: d.update(num_timesteps=-1))),
                    "'num_timesteps' must be an integer >= 0"),
    # sizes each valid for PPOConfig, whose model would not fit in memory: refused before it is built
    "oversized policy": (lambda g, p, t: _rewrite(g, p, _edit_data(
        lambda d: d["policy_kwargs"]["train_config"].update(width=4096, blocks=4096))),
        "make a policy of 137,473,163,612 parameters"),
    "a width past the cap": (lambda g, p, t: _rewrite(g, p, _edit_data(
        lambda d: d["policy_kwargs"]["train_config"].update(critic_hidden=10**6))),
        "critic_hidden must be an integer >= 1 and <= 4096, got 1000000"),
    "oversized rollout": (lambda g, p, t: _rewrite(g, p, _edit_data(
        lambda d: d["policy_kwargs"]["train_config"].update(n_steps=10**9, batch_size=64))),
        "rollout (n_steps 1000000000 x n_envs"),
}


IN_WEIGHTS = {"policy not torch", "policy a tensor", "wrong shapes", "bad counter"}
TOO_LARGE = {"oversized policy", "a width past the cap", "oversized rollout"}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_every_malformed_zip_is_one_line_naming_it(genuine, tmp_path, capsys, monkeypatch, case):
    make, what = MALFORMED[case]
    path = make(genuine, tmp_path / f"{case.replace(' ', '-')}.zip", tmp_path)
    if case in TOO_LARGE:  # refused from the stored sizes alone: building the model would allocate it
        def refuse(*args, **kwargs):
            raise AssertionError("a model was built for a zip that declares one too large")
        monkeypatch.setattr(ppo_archive, "build_model", refuse)
    if what is None:  # no optimizer state: fine for predicting, refused for continuing training
        load_ppo_actor(path)
        capsys.readouterr()
        assert main(["train", "--algo", "ppo", "--resume", str(path), "--out", str(tmp_path / "train"),
                     "--no-progress"]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and str(path) in lines[0] and "no 'policy.optimizer.pth' entry" in lines[0], lines
        return
    _assert_refused_everywhere(path, tmp_path, capsys, what, in_config=case not in IN_WEIGHTS)
    if case == "module env id":
        import sys

        assert "antigravity" not in sys.modules


def test_train_resume_of_a_zip_without_algo_ppo_says_so(genuine, tmp_path, capsys):
    assert main(["train", "--resume", str(genuine), "--out", str(tmp_path / "t"), "--no-progress"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(genuine) in lines[0] and "--algo ppo" in lines[0], lines


def test_a_genuine_zip_loads_as_sb3_would_and_acts_identically(genuine):
    """Our loader against SB3's own ``PPO.load`` on a file we wrote ourselves (trusted)."""
    from stable_baselines3 import PPO

    reference = PPO.load(str(genuine), device="cpu")
    ours = load_ppo(genuine)
    ref_state, our_state = reference.policy.state_dict(), ours.policy.state_dict()
    assert list(ref_state) == list(our_state)
    assert all(torch.equal(ref_state[k], our_state[k]) for k in ref_state)
    ref_opt, our_opt = reference.policy.optimizer.state_dict(), ours.policy.optimizer.state_dict()
    assert ref_opt["param_groups"] == our_opt["param_groups"] and ref_opt["state"].keys() == our_opt["state"].keys()
    assert all(torch.equal(ref_opt["state"][i][n], our_opt["state"][i][n])
               for i in ref_opt["state"] for n in ref_opt["state"][i])
    assert (ours.num_timesteps, ours._n_updates, ours.seed) == (reference.num_timesteps, reference._n_updates,
                                                                reference.seed) == (64, 1, 0)
    assert ours.observation_space == reference.observation_space and ours.action_space == reference.action_space
    assert read_ppo_config(genuine) == PPOConfig(**CONFIG)
    env = StereoVOEnv(n_frames=2, n_correspondences=64, budget=8)
    for seed in (5, 6):
        obs, _ = env.reset(seed=seed)
        expected, _ = reference.predict(obs, deterministic=True)
        action, _ = ours.predict(obs, deterministic=True)
        np.testing.assert_array_equal(action, expected)
        np.testing.assert_allclose(LearnedPolicy(load_ppo_actor(genuine)).act(obs), expected, atol=1e-5)
    # Continuing training from it: same counters, then one more update.
    config = read_ppo_config(genuine)
    venv = make_training_env(config)
    try:
        model = load_ppo(genuine, env=venv)
        assert model.num_timesteps == 64 and model.n_envs == 2
        model.learn(total_timesteps=64, reset_num_timesteps=False, progress_bar=False)
        assert model.num_timesteps == 128 and model._n_updates == 2
    finally:
        venv.close()
    assert os.path.getsize(genuine) > 0
