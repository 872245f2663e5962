"""Every shipped checkpoint has a model card beside it, and the card's figures name their command.

A card (``agents/checkpoints/NAME.md``) says what the sampler is, how it was trained, its feature
layout, measured results with intervals in-domain and on the transfer domains, its intended use
and its known limits. Every section that states a rate names the command that regenerates it, and
the transfer results are exactly what that command wrote to ``docs/data/transfer.csv``.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from agents.transfer import (
    BEGIN,
    END,
    PUBLISHED,
    model_card_block,
    read_results,
    regenerate_command,
    transfer_markdown,
)
from vo_gym.features import FEATURE_LAYOUT_VERSION

ROOT = Path(__file__).resolve().parents[1]
FOLDER = ROOT / "agents" / "checkpoints"
CHECKPOINTS = sorted(FOLDER.glob("*.pt"))
HEADINGS = ("## What it is", "## Training", "## Feature layout", "## Measured results", "## Intended use",
            "## Known limits")
RATE = re.compile(r"\d(\.\d+)? ?%")
REGENERATE = re.compile(r"Regenerate: `([^`]+)`")


def sections(text: str) -> list[str]:
    return re.split(r"\n(?=##+ )", text)


def between(text: str) -> str:
    return text.split(BEGIN)[1].split(END)[0].strip()


def test_every_checkpoint_has_a_card_and_every_card_a_checkpoint():
    assert CHECKPOINTS
    assert {p.stem for p in CHECKPOINTS} == {p.stem for p in FOLDER.glob("*.md")}


@pytest.mark.parametrize("path", CHECKPOINTS, ids=lambda p: p.stem)
def test_a_card_holds_every_section_and_its_layout(path):
    from agents import load_sampler

    text = path.with_suffix(".md").read_text()
    assert text.startswith(f"# Model card: `{path.stem}`")
    positions = [text.find(h) for h in HEADINGS]
    assert -1 not in positions and positions == sorted(positions), positions
    policy = load_sampler(path)
    assert f"Kind: {policy.kind}" in text
    assert f"layout version {FEATURE_LAYOUT_VERSION}" in text
    if policy.kind == "in-frame":
        from agents.adaptive import FORMAT

        assert f"Format `{FORMAT}`" in text
    assert "in-domain" in text and "transfer" in text


@pytest.mark.parametrize("path", CHECKPOINTS, ids=lambda p: p.stem)
def test_every_rate_names_the_command_that_regenerates_it(path):
    for section in sections(path.with_suffix(".md").read_text()):
        if not RATE.search(section):
            continue
        commands = REGENERATE.findall(section)
        assert commands, f"{path.stem}: a section states a rate without its command:\n{section[:200]}"
        for command in commands:
            words = shlex.split(command)
            if words[0].startswith("scripts/"):
                assert (ROOT / words[0]).is_file(), command
            elif words[:2] == ["python", "-m"]:
                assert (ROOT / (words[2].replace(".", "/") + ".py")).is_file(), command
            else:
                assert words[0] == "vo-gym", command


def test_the_transfer_figures_are_what_their_command_wrote():
    results = read_results(ROOT / PUBLISHED["csv"])
    command = regenerate_command(results)
    assert min(r["frames"] for r in results) >= 300  # the minimum a cell
    for path in CHECKPOINTS:
        text = path.with_suffix(".md").read_text()
        assert between(text) == model_card_block(results, path.stem, command).strip(), path.stem
        assert {r["sampler"] for r in results} >= {path.stem}
    doc = (ROOT / PUBLISHED["results"]).read_text()
    assert between(doc) == transfer_markdown(results, command).strip()
    assert (ROOT / PUBLISHED["figure"]).is_file()
