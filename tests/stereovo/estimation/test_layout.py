"""stereovo.estimation is arranged by role, and each method option has one home.

The layout: the core at the top of the package (at most 12 modules), every compiled kernel under
``kernels/``, imports at the top of each module and of names from the module that defines them.
The options: a method's declarations carry each option's rule and default, and its recipe runs on
exactly those defaults when the caller gives none.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from stereovo.estimation import available_methods, estimate_motion, method_spec
from stereovo.estimation.estimator_options import EstimatorOptions
from stereovo.estimation.problem import StereoProblem
from stereovo.simulation import SimulationConfig, simulate_frame

ROOT = Path(__file__).resolve().parents[3]
ESTIMATION = ROOT / "stereovo" / "estimation"
PACKAGES = ("stereovo", "vo_gym", "agents", "vo_gym_cli")


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}
PACKAGE_MODULES = {name for name, path in MODULES.items() if path.name == "__init__.py"}


def _defined(tree: ast.Module) -> set[str]:
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
    return names


def test_the_top_of_the_package_holds_at_most_twelve_modules():
    top = sorted(p.name for p in ESTIMATION.glob("*.py"))
    assert len(top) <= 12, top
    assert {"api.py", "problem.py", "registry.py", "loop.py", "recipes.py", "covariance.py"} <= set(top)


def test_every_compiled_kernel_lives_under_kernels():
    outside = [
        str(path.relative_to(ROOT))
        for path in sorted(ESTIMATION.rglob("*.py"))
        if "kernels" not in path.relative_to(ESTIMATION).parts
        and any(isinstance(n, (ast.Import, ast.ImportFrom)) and "numba" in ((n.module or "") if isinstance(n, ast.ImportFrom)
                else " ".join(a.name for a in n.names)) for n in ast.walk(ast.parse(path.read_text())))
    ]
    assert outside == []


@pytest.mark.parametrize("path", sorted(ESTIMATION.rglob("*.py")), ids=lambda p: str(p.relative_to(ESTIMATION)))
def test_imports_stand_at_the_top_of_each_module(path):
    body = ast.parse(path.read_text()).body
    first_code = next((i for i, n in enumerate(body) if not isinstance(n, (ast.Import, ast.ImportFrom))
                       and not (i == 0 and isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))), len(body))
    late = [n.lineno for n in body[first_code:] if isinstance(n, (ast.Import, ast.ImportFrom))]
    assert late == []


def test_estimation_names_are_imported_from_the_module_that_defines_them():
    # a package (its __init__) may gather public names; a plain module is asked only for its own
    defined = {name: _defined(ast.parse(MODULES[name].read_text())) for name in MODULES if name.startswith("stereovo.estimation")}
    through = [
        f"{source}: from {node.module} import {alias.name}"
        for source, path in MODULES.items()
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("stereovo.estimation")
        and node.module in defined and node.module not in PACKAGE_MODULES
        for alias in node.names
        if alias.name not in defined[node.module]
    ]
    assert through == []


# ----------------------------------------------------------------------------- one home per option

FRAME = simulate_frame(SimulationConfig(n_correspondences=120, outlier_ratio=0.3), rng=5)
INPUTS = {"prosac": {"order": np.argsort(-FRAME.scores, kind="stable")}, "guided-mlesac": {"priors": FRAME.scores}}



@pytest.mark.parametrize("name", [m for m in available_methods() if method_spec(m).extra_options])
def test_every_method_option_is_declared_with_a_default_its_rule_accepts(name):
    spec = method_spec(name)
    for option in spec.extra_options:
        rule = spec.option_rule(option)
        assert rule is not None, option
        assert rule.check(option, rule.default) == rule.default
    assert set(spec.option_defaults()) == set(spec.extra_options)


@pytest.mark.parametrize("name", ["mlesac", "r-ransac", "waldsac", "lo-ransac", "preemptive", "usac", "bansac",
                                  "p-bansac", "ars", "inlier-detection"])
def test_a_method_run_without_its_options_runs_on_their_declared_defaults(name):
    kw = INPUTS.get(name, {})
    bare = estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method=name, rng=3, **kw)
    explicit = estimate_motion(FRAME.prev, FRAME.curr, FRAME.camera, method=name, rng=3, **kw,
                               **method_spec(name).option_defaults())
    assert bare.status == explicit.status
    np.testing.assert_array_equal(bare.rotation, explicit.rotation)
    np.testing.assert_array_equal(bare.inliers, explicit.inliers)
    assert (bare.n_hypotheses, bare.n_scored) == (explicit.n_hypotheses, explicit.n_scored)


def _components(name: str, extra: dict, **inputs):
    problem = StereoProblem.build(FRAME.prev, FRAME.curr, FRAME.camera, 1.0)
    return method_spec(name).build(problem, EstimatorOptions(), inputs.get("priors"), inputs.get("order"), extra)


def _default(name: str, option: str):
    return method_spec(name).option_rule(option).default


def test_a_recipe_built_without_options_holds_the_declared_defaults():
    # what a recipe holds when nobody passes the option (the environment builds recipes directly)
    mlesac = _components("mlesac", {}).quality
    assert (mlesac.em_iterations, mlesac.em_tolerance) == (
        _default("mlesac", "mlesac_em_iterations"), _default("mlesac", "mlesac_em_tolerance"))
    assert _components("r-ransac", {}).verifier.d == _default("r-ransac", "tdd_d")
    sprt = _components("waldsac", {}).verifier
    assert (sprt.t_m, sprt.epsilon0, sprt.delta0, sprt.chunk) == tuple(
        _default("waldsac", o) for o in ("sprt_t_m", "sprt_epsilon0", "sprt_delta0", "sprt_chunk"))
    lo = _components("lo-ransac", {}).local_optimizer
    assert (lo.inner_iterations, lo.sample_cap, lo.threshold_multiplier, lo.steps) == tuple(
        _default("lo-ransac", o) for o in ("lo_inner_iterations", "lo_sample_cap", "lo_threshold_multiplier", "lo_steps"))
    assert _components("preemptive", {}).verifier.block == _default("preemptive", "preemptive_block")
    stop = _components("prosac", {}, order=INPUTS["prosac"]["order"]).termination
    assert (stop.beta, stop.psi, stop.min_n) == tuple(
        _default("prosac", o) for o in ("prosac_beta", "prosac_psi", "prosac_min_n"))
    assert _components("p-bansac", {}).sampler.threshold == _default("p-bansac", "bansac_threshold")
    # and a value given is the value held
    assert _components("r-ransac", {"tdd_d": 3}).verifier.d == 3


def test_methods_are_listed_core_first_then_by_paper_then_the_variants():
    # the registration order is the order of the baseline report's rows and of the CLI's help
    names = list(available_methods())
    assert names[:3] == ["ransac", "msac", "probabilistic"]
    assert names[3:15] == ["mlesac", "guided-mlesac", "prosac", "r-ransac", "waldsac", "lo-ransac", "preemptive",
                           "usac", "inlier-detection", "bansac", "p-bansac", "ars"]
    assert all("+" in name for name in names[15:])
