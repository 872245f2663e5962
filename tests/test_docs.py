"""The documents run: every Python block of README.md and docs/*.md, and what they point to exists.

A block may be skipped only with a reason, written on the line before its fence as
``<!-- skip-test: why -->`` (for instance a training run of many minutes). The blocks of one file
run in order in one namespace, from a temporary working directory, so a later block may use what
an earlier one defined and nothing lands in the repository.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import io
import os
import re
from pathlib import Path

import pytest

from stereovo.estimation import available_methods

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SKIP = re.compile(r"<!--\s*skip-test:\s*(?P<reason>\S.*?)\s*-->")
FENCE = re.compile(r"^```(?P<lang>[\w+-]*)\s*$")

TEST_COMMAND = "./scripts/setup.sh && .venv/bin/python -m pytest -n 2"
MAIN_JOB = (
    "./scripts/setup.sh && .venv/bin/vo-gym baselines --out runs/baselines --overwrite && .venv/bin/vo-gym evaluate "
    "--agent agents/checkpoints/ngransac-supervised.pt --agent agents/checkpoints/ppo.pt --agent uniform "
    "--epsilons 0.5,0.8 --budgets 4,16,64 --out runs/evaluate --overwrite"
)


def python_blocks(path: Path) -> list[tuple[int, str, str | None]]:
    """``(first line number, code, skip reason or None)`` of each ```python block of ``path``."""
    lines = path.read_text().splitlines()
    blocks, i = [], 0
    while i < len(lines):
        match = FENCE.match(lines[i])
        if match is None:
            i += 1
            continue
        start, lang = i, match["lang"]
        end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("```")), None)
        assert end is not None, f"{path.name}:{start + 1}: a code block is never closed"
        if lang == "python":
            previous = next((lines[j] for j in range(start - 1, -1, -1) if lines[j].strip()), "")
            skip = SKIP.search(previous)
            blocks.append((start + 2, "\n".join(lines[start + 1:end]) + "\n", skip["reason"] if skip else None))
        i = end + 1
    return blocks


@pytest.fixture
def one_torch_thread():
    """Examples with small networks run on one torch thread (restored afterwards): on a machine whose
    cores are shared, torch's extra intra-op threads only contend (measured 20x slower)."""
    try:
        import torch
    except ImportError:
        yield
        return
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


WITH_EXAMPLES = [path for path in DOCUMENTS if any(skip is None for _, _, skip in python_blocks(path))]
"""The documents with at least one Python block that is meant to run (the others have none to test)."""


@pytest.mark.parametrize("path", WITH_EXAMPLES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_python_block_runs(path, tmp_path, monkeypatch, one_torch_thread):
    """Each block runs in turn, in one namespace per document, without raising."""
    blocks = [(line, code) for line, code, skip in python_blocks(path) if skip is None]
    assert blocks
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__doc_example__"}
    for line, code in blocks:
        with contextlib.redirect_stdout(io.StringIO()):
            # the file name and line in the code object make a traceback point at the document
            exec(compile("\n" * (line - 1) + code, str(path), "exec"), namespace)


def test_the_user_documents_hold_examples_that_run():
    assert {p.name for p in WITH_EXAMPLES} >= {"README.md", "algorithms.md", "images.md"}


def test_the_readme_holds_its_examples_and_its_two_commands():
    readme = (ROOT / "README.md").read_text()
    assert TEST_COMMAND in readme and MAIN_JOB in readme
    assert len(readme.splitlines()) <= 200
    blocks = python_blocks(ROOT / "README.md")
    assert len(blocks) >= 4 and all(skip is None for _, _, skip in blocks)
    code = "\n".join(c for _, c, _ in blocks)
    for needle in ("simulate_frame", "gym.make", "load_sampler(", "EquivariantActorCriticPolicy", "progress_bar=True"):
        assert needle in code, needle


def test_the_ci_runs_the_readme_test_command():
    assert TEST_COMMAND in (ROOT / ".ci" / "run").read_text()


def test_skip_markers_give_a_reason():
    for path in DOCUMENTS:
        for line, _, skip in python_blocks(path):
            assert skip is None or len(skip) >= 10, f"{path.name}:{line}: a skip needs a reason"


@pytest.mark.parametrize("path", DOCUMENTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_point_to_files(path):
    text = path.read_text()
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
        if "://" in target:
            continue
        assert (path.parent / target).exists(), f"{path.name} links to {target}, which does not exist"


def _github_anchor(heading: str) -> str:
    """The id GitHub gives a heading: its text (code marks and link targets dropped) lower-cased,
    characters other than letters, digits, ``_``, ``-`` and spaces removed, spaces made hyphens."""
    text = re.sub(r"`|\*\*|\[([^\]]*)\]\([^)]*\)", lambda m: m.group(1) or "", heading.strip()).lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    """The ids of a markdown file's headings; a repeated one gets -1, -2, ... as on GitHub."""
    seen: dict[str, int] = {}
    anchors = set()
    fenced = False
    for line in path.read_text().splitlines():
        fenced ^= line.startswith("```")
        heading = None if fenced else re.match(r"^#{1,6} (.*)$", line)
        if heading:
            slug = _github_anchor(heading.group(1))
            seen[slug] = seen.get(slug, -1) + 1
            anchors.add(slug if seen[slug] == 0 else f"{slug}-{seen[slug]}")
    return anchors


@pytest.mark.parametrize("path", DOCUMENTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_to_a_heading_name_one_that_exists(path):
    for target, anchor in re.findall(r"\]\(([^)#\s]*)#([^)\s]+)\)", path.read_text()):
        linked = path if not target else path.parent / target
        if "://" in target or linked.suffix != ".md":
            continue
        assert anchor in _anchors(linked), f"{path.name} links to {target}#{anchor}, a heading {linked.name} lacks"


def test_every_registered_method_has_its_section_in_algorithms():
    text = (ROOT / "docs" / "algorithms.md").read_text()
    sections = set(re.findall(r"^### `([^`]+)`", text, flags=re.M))
    for name in available_methods():
        if "+" in name:  # the "+ enhancement" variants share one section, each named in it
            assert f"`{name}`" in text, f"docs/algorithms.md does not name {name}"
        else:
            assert name in sections, f"docs/algorithms.md has no section for method {name!r}"
    for name in sections - {"+ enhancement"}:
        assert name in available_methods() or name.startswith("+"), f"section for unknown method {name!r}"


def test_algorithms_names_test_files_that_exist():
    text = (ROOT / "docs" / "algorithms.md").read_text()
    named = set(re.findall(r"`(tests/[\w/]+\.py)`", text))
    assert named and all((ROOT / p).is_file() for p in named), sorted(p for p in named if not (ROOT / p).is_file())


# rl-zoo3's own keys (consumed by its ExperimentManager before the algorithm is built); every other
# key of a hyperparameter entry is passed to the algorithm's constructor.
ZOO_KEYS = {"n_envs", "n_timesteps", "policy", "policy_kwargs", "normalize", "env_wrapper", "vec_env_wrapper",
            "frame_stack", "callback", "monitor_kwargs"}


def test_the_rl_zoo3_hyperparameters_build_the_equivariant_ppo():
    yaml = pytest.importorskip("yaml")
    pytest.importorskip("stable_baselines3")
    import gymnasium as gym
    from stable_baselines3 import PPO

    import vo_gym  # noqa: F401
    from agents.ppo.policy import EquivariantActorCriticPolicy

    config = yaml.safe_load((ROOT / "configs" / "rl-zoo3" / "ppo.yml").read_text())
    assert set(config) == {"vo_gym/StereoVO-v0"}
    entry = dict(config["vo_gym/StereoVO-v0"])
    ppo_args = set(inspect.signature(PPO.__init__).parameters) - {"self", "policy", "env"}
    assert set(entry) - ZOO_KEYS <= ppo_args, sorted(set(entry) - ZOO_KEYS - ppo_args)
    assert entry["normalize"] is False  # VecNormalize would rescale the validity mask
    # the zoo imports a policy given by a dotted name, and evaluates a policy_kwargs string
    module, _, name = entry.pop("policy").rpartition(".")
    assert getattr(importlib.import_module(module), name) is EquivariantActorCriticPolicy
    policy_kwargs = eval(entry.pop("policy_kwargs"), {})  # noqa: S307 - our own file, as rl-zoo3 does
    n_envs, n_timesteps = entry.pop("n_envs"), entry.pop("n_timesteps")
    assert n_envs >= 1 and n_timesteps >= entry["n_steps"] * n_envs
    entry.pop("normalize")
    env = gym.make("vo_gym/StereoVO-v0", n_correspondences=100, n_frames=8, budget=16, outlier_ratio=(0.3, 0.9))
    try:
        model = PPO(EquivariantActorCriticPolicy, env, policy_kwargs=policy_kwargs, device="cpu", seed=0, **entry)
        assert model.n_steps == entry["n_steps"] and model.policy.width == policy_kwargs["width"]
    finally:
        env.close()


def test_documents_do_not_point_outside_the_repository():
    for path in DOCUMENTS:
        text = path.read_text()
        for name in ("ALGORITHMS.md", "DESIGN.md"):
            assert name not in text, f"{path.name} cites {name}, which is not part of the repository"
    assert os.path.exists(ROOT / "LICENSE")


def test_no_file_cites_references_outside_the_repository():
    # Code, tests, scripts and configs cite papers or docs/, never the design notes kept outside the clone;
    # this file is the one that may name them, to check that they are absent.
    suffixes = {".py", ".md", ".sh", ".toml", ".yml", ".yaml", ".cfg", ".txt"}
    files = [path for path in ROOT.iterdir() if path.is_file() and path.suffix in suffixes]
    for folder in ("stereovo", "vo_gym", "agents", "tests", "scripts", "docs", "configs"):
        files += [path for path in (ROOT / folder).rglob("*") if path.is_file() and path.suffix in suffixes]
    offenders = [
        str(path.relative_to(ROOT))
        for path in files
        if path != Path(__file__).resolve() and any(name in path.read_text(errors="replace") for name in ("ALGORITHMS.md", "DESIGN.md"))
    ]
    assert not offenders, f"these files cite ALGORITHMS.md / DESIGN.md, which are not part of the repository: {offenders}"
