"""What every ``vo-gym`` command shares besides its argument types
(:mod:`vo_gym_cli.commands.arguments`): the parser and its help, the usage-error type, the record
of the options typed, the output-folder check made before any computing, and the one-line handling
of usage errors and Ctrl-C.

Conventions (argparse's): a usage error prints one line ``vo-gym CMD: error: ...``
naming the argument and exits 2; Ctrl-C prints one line and exits 130.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


class UsageError(Exception):
    """A bad argument or unusable path; the message names the argument and the value."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line, ``vo-gym CMD: error: MESSAGE``, exit 2.

    The usage synopsis is left out (``--help`` shows it), and argparse's ``argument --x: --x ...``
    prefix is shortened when the message names the option itself.
    """

    def error(self, message: str):  # type: ignore[override]
        match = re.match(r"argument ([^:]+): (.*)$", message, flags=re.S)
        if match and match.group(2).startswith(match.group(1).split("/")[0]):
            message = match.group(2)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {' '.join(message.split())}\n")


LATE_HELP = "late_help"
"""The attribute of an option (set by :func:`late_help`) that maps ``NAME`` to a function making the
text of ``{NAME}`` in its help, called only when ``--help`` is formatted."""


def late_help(action: argparse.Action, **parts: Callable[[], str]) -> argparse.Action:
    """Let :class:`HelpFormatter` replace ``{NAME}`` in ``action``'s help by ``parts[NAME]()`` when the
    help is formatted: text read from a library (a trainer config's defaults) that building the
    parser must not import, so that ``vo-gym`` starts fast. Returns ``action``."""
    setattr(action, LATE_HELP, dict(parts))
    return action


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Every option's help ends with its default, unless the text already states one.

    Flags (``store_true``) and options whose default is None (meaning "the library's default",
    which their text then names) get nothing appended; descriptions and epilogs keep their lines.
    ``{NAME}`` parts of an option's help that :func:`late_help` declared are made here.
    """

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        for name, make in getattr(action, LATE_HELP, {}).items():
            text = text.replace("{" + name + "}", make().replace("%", "%%"))
        if (
            "default" in text
            or action.default is None
            or action.default is argparse.SUPPRESS
            or action.nargs == 0  # flags: store_true / store_false / help / version
            or not action.option_strings
        ):
            return text
        default = action.default
        if isinstance(default, (list, tuple)):
            shown = ",".join(str(v) for v in default)
        else:
            shown = str(default)
        return f"{text} (default: {shown.replace('%', '%%')})".strip()


def render_pairs(source: str, preset: str, n_frames: int, seed: int, resolution: str,
                 advance: Callable[[], None] | None = None) -> tuple[list, Any]:
    """Frame pairs ``1..n_frames`` of a rendered sequence, matched by the front end, and the
    (closed) sequence, whose ``camera``, ``true_poses`` and ``noise_sigma`` stay readable.

    ``advance`` is called after each pair (a progress bar's ``update``).

    Raises:
        UsageError: naming ``--source`` when the machine cannot render headless.
    """
    from stereovo.sequences.rendered import RenderedSequence
    from stereovo.sequences.rendering import RenderingUnavailable

    try:
        sequence = RenderedSequence(preset, n_frames=n_frames, seed=seed, resolution=resolution)
    except RenderingUnavailable as err:
        raise UsageError(f"--source {source}: {' '.join(str(err).split())}") from None
    try:
        frames = []
        for k in range(1, n_frames + 1):
            frames.append(sequence.frame(k))
            if advance is not None:
                advance()
    finally:
        sequence.close()
    return frames, sequence


GIVEN_OPTIONS = "given_options"
"""The attribute of the parsed arguments that :func:`vo_gym_cli.main.main` hands a command: a dict
from each option typed on the command line (its argparse dest) to the option string as typed
(``--out``, or a prefix that argparse accepts, such as ``--overw``), in the order typed. An option
left out is absent from it, and one typed at its default value is present: "given" means typed."""


def _actions(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    # argparse offers no public way to list a parser's arguments; this is the one place the CLI reads
    # its private list.
    return parser._actions


def _command_parser(add_parser: Callable[[argparse.ArgumentParser], None], prog: str | None) -> ArgumentParser:
    parser = ArgumentParser(prog=prog)
    add_parser(parser)
    return parser


def typed_options(add_parser: Callable[[argparse.ArgumentParser], None], argv: list[str],
                  prog: str | None = None) -> dict[str, str]:
    """The options that a command's own arguments ``argv`` (after its name) type, as
    :data:`GIVEN_OPTIONS` records them; ``add_parser`` declares the command's options.

    ``argv`` is parsed again by argparse itself with every default suppressed, so that an option
    left out leaves no attribute, whatever its default; the spelling comes from ``argv``'s tokens.
    """
    parser = _command_parser(add_parser, prog)
    options = [action for action in _actions(parser) if action.option_strings]
    # On each action rather than through set_defaults(), whose SUPPRESS argparse would still write
    # into the namespace (converted by the option's type, which fails on that text).
    for action in options:
        action.default = argparse.SUPPRESS
    typed = vars(parser.parse_args(argv))
    spelled = _spellings(options, argv)
    by_dest = {action.dest: action for action in options}
    return {dest: spelled.get(dest, by_dest[dest].option_strings[0]) for dest in typed if dest in by_dest}


def _spellings(options: list[argparse.Action], argv: list[str]) -> dict[str, str]:
    """Each dest -> the option string by which ``argv`` first names it: an alias, ``--x`` of
    ``--x=VALUE``, or the unambiguous prefix of a long option that argparse accepts for it."""
    dest_of = {string: action.dest for action in options for string in action.option_strings}
    spelled: dict[str, str] = {}
    for token in argv:
        if token == "--":  # what follows is positional, whatever it looks like
            break
        name = token.partition("=")[0]
        if name in dest_of:
            spelled.setdefault(dest_of[name], name)
        elif name.startswith("--"):
            dests = {dest for string, dest in dest_of.items() if string.startswith(name)}
            if len(dests) == 1:
                spelled.setdefault(dests.pop(), name)
    return spelled


def given_options(args: argparse.Namespace, add_parser: Callable[[argparse.ArgumentParser], None]) -> dict[str, str]:
    """The options given to a command, dest -> flag: the :data:`GIVEN_OPTIONS` record of ``args``.

    A Namespace that carries no record (built by hand, or by ``build_parser().parse_args`` rather
    than ``main``) cannot say what was typed; there, and only there, an option counts as given when
    its value differs from the parser's default, shown by its first option string.
    """
    recorded = getattr(args, GIVEN_OPTIONS, None)
    if recorded is not None:
        return dict(recorded)
    parser = _command_parser(add_parser, None)
    defaults = vars(parser.parse_args([]))
    return {action.dest: action.option_strings[0] for action in _actions(parser)
            if action.option_strings and action.dest in defaults
            and getattr(args, action.dest, defaults[action.dest]) != defaults[action.dest]}


def shown_value(value: Any) -> str:
    """An option's value as it follows the flag in a message: nothing for a flag, ``A,B`` for a list,
    an integer of hundreds of digits by its magnitude (:func:`stereovo.options.value_repr`)."""
    if isinstance(value, bool):
        return ""
    if isinstance(value, (list, tuple)):
        return " " + ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)
    if isinstance(value, int) and value.bit_length() > 200:
        from stereovo.options import value_repr

        return f" {value_repr(value)}"
    return f" {value}"


def unread_option(args: argparse.Namespace, add_parser: Callable[[argparse.ArgumentParser], None],
                  read_by: dict[str, frozenset[str]], run: str) -> tuple[str, str, list[str]] | None:
    """The first option given to a command with several kinds of run that ``run`` does not read:
    ``(the flag as typed and its value, dest, the runs that read it)``, or None.

    ``read_by`` maps each run to the argparse dests it reads; a dest in none of them serves every
    run. "Given" is :func:`given_options`': typed on the command line, even at its default value.
    """
    read_anywhere = frozenset().union(*read_by.values())
    for dest, flag in given_options(args, add_parser).items():
        if dest in read_by[run] or dest not in read_anywhere:
            continue
        return flag + shown_value(getattr(args, dest)), dest, [r for r, read in read_by.items() if dest in read]
    return None


def open_run_folder(args: argparse.Namespace, resumable: bool = True) -> Path:
    """``--out`` refused when not empty (unless --resume / --overwrite), then proved writable.

    A run that keeps no journal (``resumable=False``: its caller refuses ``--resume``) is pointed to
    ``--overwrite`` alone, since the usual hint would offer a --resume it cannot honour.
    """
    from stereovo.trials import RunFolderError, prepare_run_folder

    try:
        prepare_run_folder(args.out, resume=bool(args.resume) and resumable, overwrite=args.overwrite)
    except RunFolderError as err:
        if resumable:
            raise UsageError(str(err)) from None
        raise UsageError(f"--out {str(args.out)!r} is not empty; pass --overwrite to replace the run there") from None
    return check_output_dir(args.out)


def check_output_dir(path: str | os.PathLike, option: str = "--out") -> Path:
    """Create ``path`` if needed and prove it writable, before any computing starts.

    Raises:
        UsageError: naming ``option`` and the path when it is a file, cannot be created,
            or cannot be written.
    """
    shown = str(path)
    # Lexically, as a shell would (X/missing/../Y is X/Y), like prepare_run_folder's emptiness check:
    # through a missing folder mkdir(parents=True) would create it and write into a full Y unchecked.
    out = Path(os.path.normpath(path))
    if out.exists() and not out.is_dir():
        raise UsageError(f"{option} {shown!r} exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".write-check-"):
            pass
    except OSError as err:
        raise UsageError(f"{option} {shown!r} is not writable ({err.strerror or err})") from None
    return out


class RunStart:
    """What ``--out`` held before a run started, so that a start that fails leaves it as it was.

    Construct it before anything is written; :meth:`undo` removes every entry that was not there
    (the journal and manifest a failed start opened, the folder itself if it was created).
    """

    def __init__(self, out: str | os.PathLike) -> None:
        self.out = Path(out)
        self.existed = self.out.is_dir()
        self.before = {p.name for p in self.out.iterdir()} if self.existed else set()

    def undo(self) -> None:
        import shutil

        if not self.out.is_dir():
            return
        for entry in self.out.iterdir():
            if entry.name not in self.before:
                if entry.is_dir() and not entry.is_symlink():
                    shutil.rmtree(entry, ignore_errors=True)
                else:
                    entry.unlink(missing_ok=True)
        if not self.existed:
            with contextlib.suppress(OSError):
                self.out.rmdir()


def flag_error(flag: str, err: Exception) -> UsageError:
    """A library's range error as a usage error naming ``flag``: its leading field name
    (``SimulationConfig.outlier_ratio must ...``, ``epsilons must ...``) becomes the flag."""
    text = str(err)
    if text.startswith(flag):
        return UsageError(text)
    rule = re.sub(r"^(?:[A-Za-z_]+\.)?[a-z_ ]+? (?=must |needs )", "", text, count=1)
    return UsageError(f"{flag} {rule}" if rule != text else f"{flag}: {text}")


def check_step_env(env_id: str, in_frame_hint: str, images_hint: str, option: str = "--env-id") -> None:
    """Refuse an in-frame or image id (:func:`vo_gym.registration.env_kind`), which a one-shot sampler
    cannot step, in one line naming ``option`` and the id and ending with the command's hint (what to
    use instead), before any header or folder. An unknown id, or one of another package, passes: each
    command names those its own way.

    Raises:
        UsageError: ``OPTION ID is an in-frame environment (...); IN_FRAME_HINT`` or ``OPTION ID is an
            image environment; IMAGES_HINT``.
    """
    from vo_gym.registration import IMAGES, IN_FRAME, env_kind

    kind = env_kind(env_id)
    if kind == IN_FRAME:
        raise UsageError(f"{option} {env_id} is an in-frame environment (its action also stops the search); "
                         f"{in_frame_hint}")
    if kind == IMAGES:
        raise UsageError(f"{option} {env_id} is an image environment; {images_hint}")


def check_output_file(path: str | os.PathLike, option: str = "--out") -> Path:
    """Prove a file can be written at ``path`` (its folder created if needed), before any computing.

    Raises:
        UsageError: naming ``option`` and the path when it is a folder or cannot be written.
    """
    out = Path(path)
    if out.is_dir():
        raise UsageError(f"{option} {str(out)!r} is a directory, not a file")
    check_output_dir(out.parent if str(out.parent) else Path("."), option)
    if out.exists() and not os.access(out, os.W_OK):
        raise UsageError(f"{option} {str(out)!r} is not writable")
    return out


def score_inputs(method: str) -> dict[str, Any]:
    """``priors_fn`` / ``order_fn`` (``frame -> array``) that feed a method the frames' match scores
    when it needs them: PROSAC-style methods get the scores' ranking (best first), methods that need
    priors (guided MLESAC's gamma_i) the scores calibrated to inlier probabilities
    (``Frame.match_probabilities``); others get neither (uniform sampling)."""
    import numpy as np

    from stereovo.estimation import method_spec

    needs = method_spec(method).inputs
    if needs == "order":
        return {"order_fn": lambda frame: np.argsort(-frame.scores, kind="stable")}
    if needs == "priors":
        return {"priors_fn": lambda frame: frame.match_probabilities}
    return {}


def quiet_pool_exit(unraisable) -> None:
    """``sys.unraisablehook`` that drops one known stdlib race and passes everything else on.

    After an interrupted process pool, CPython 3.11's ``concurrent.futures.process._python_exit``
    (run at interpreter exit) can write to the pool's already closed wake-up pipe and print an
    "Exception ignored ... OSError: [Errno 9] Bad file descriptor" traceback after our one-line
    message (seen about one run in seven). Nothing is lost: the pool is shut down, its trials
    journaled.
    """
    tb = unraisable.exc_traceback
    frames = []
    while tb is not None:
        frames.append(tb.tb_frame.f_code.co_filename)
        tb = tb.tb_next
    if isinstance(unraisable.exc_value, OSError) and any(f.endswith(("concurrent/futures/process.py",
                                                                      "multiprocessing/connection.py")) for f in frames):
        return
    sys.__unraisablehook__(unraisable)


EXTRAS = {
    "torch": "train", "stable_baselines3": "train", "tensorboard": "train", "rich": "train",
    "ray": "distributed", "yaml": "distributed",
    "cv2": "peers", "poselib": "peers",
    "moderngl": "render", "glcontext": "render", "skimage": "images",
}
"""Top-level module -> the ``pip install 'vo-gym[EXTRA]'`` extra that provides it (pyproject.toml)."""


def missing_extra(err: ModuleNotFoundError) -> str | None:
    """The one-line hint for a module of an optional extra that is not installed, or None (not ours)."""
    root = (err.name or "").partition(".")[0]
    extra = EXTRAS.get(root)
    if extra is None:
        return None
    return f"this needs the '{extra}' extra ({root} is not installed): pip install 'vo-gym[{extra}]'"


def installed(module: str) -> bool:
    """Whether ``module`` can be imported (found without importing it)."""
    import importlib.util

    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent that is no package, a half-removed module
        return False


def require_extras(*modules: str) -> None:
    """Check, before anything is written, that the optional modules a command will import are installed.

    Raises:
        UsageError: the one-line ``pip install 'vo-gym[EXTRA]'`` hint of the first one missing.
    """
    for module in modules:
        if not installed(module):
            raise UsageError(missing_extra(ModuleNotFoundError(name=module)) or f"{module} is not installed")


def require_extra(extra: str, *modules: str, context: str = "") -> None:
    """Like :func:`require_extras` for modules that more than one extra provides (OpenCV is in
    ``peers`` and ``images``): the hint names ``extra``, after ``context`` (e.g. the option).

    Raises:
        UsageError: ``CONTEXT: this needs the 'EXTRA' extra (MODULE is not installed): pip install ...``.
    """
    for module in modules:
        if not installed(module):
            lead = f"{context}: " if context else ""
            raise UsageError(f"{lead}this needs the '{extra}' extra ({module} is not installed): "
                             f"pip install 'vo-gym[{extra}]'")


def one_line(message: str) -> str:
    """``message`` on one line: a line break it holds (a typed value's, a library's multi-line text)
    written as ``\\n``, as ``repr`` writes it."""
    return message.replace("\r", "\\r").replace("\n", "\\n")


def guarded(command: str, run: Callable[[], int]) -> int:
    """Run a command body; usage errors and Ctrl-C become one line and exit codes 2 / 130, and so
    does a missing optional extra (its ``pip install`` line, exit 2)."""
    try:
        code = int(run() or 0)
    except UsageError as err:
        print(f"vo-gym {command}: error: {one_line(str(err))}", file=sys.stderr)
        return EXIT_USAGE
    except ValueError as err:
        from stereovo.simulation import InfeasibleSettingsError  # only on this path: the parser stays light

        if not isinstance(err, InfeasibleSettingsError):
            raise
        # settings that passed their checks but the simulator cannot draw a frame from (its message
        # names them and what to change), raised once frames are drawn
        print(f"vo-gym {command}: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except ModuleNotFoundError as err:
        hint = missing_extra(err)
        if hint is None:
            raise
        print(f"vo-gym {command}: error: {hint}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"vo-gym {command}: interrupted", file=sys.stderr)
        code = EXIT_INTERRUPTED
    if code == EXIT_INTERRUPTED:
        sys.unraisablehook = quiet_pool_exit
    return code


def stoppable(command: str, run: Callable[[], int]) -> int:
    """:func:`guarded`, with SIGTERM (``kill``, a scheduler's stop) stopping the run as Ctrl-C does:
    for the commands that journal their work and stop cleanly."""
    from stereovo.trials.runner import sigterm_as_interrupt

    with sigterm_as_interrupt():
        return guarded(command, run)


def interrupted_run(journal: Any, stop: BaseException, total: int, out: Path) -> int:
    """Close the journal of a run that stopped (a worker's ``RunInterrupted``, or Ctrl-C / SIGTERM as
    ``KeyboardInterrupt``), print its one line (what is kept, how to resume) and return
    :data:`EXIT_INTERRUPTED`; ``total`` is the run's units of work, ``out`` its folder."""
    from stereovo.trials import RunInterrupted
    from stereovo.trials.runner import interrupted_message

    journal.close()
    message = stop.message() if isinstance(stop, RunInterrupted) else interrupted_message(len(journal.read()), total, out)
    print(message, file=sys.stderr)
    return EXIT_INTERRUPTED

