"""The docs stay true to the code: every ``thermotouch`` command they show parses, every bench they name exists.

Commands are taken from README.md and docs/*.md -- from fenced code blocks (one command per shell line,
``\\`` continuations joined, ``# comments`` and ``&&`` chains split off) and from inline code spans that
start with ``thermotouch``.  Inline spans are often synopses (``[--json]``, ``(--port PORT | --sim
SCENE)``, ``quick|standard|precise``, ``FILE.csv``): each is expanded twice -- with every optional group
and with none, the first of each set of alternatives -- and its placeholders replaced by a value the
option's own type accepts, then parsed by the CLI's parser (``host.cli.main.build_parser``; nothing runs).
The parser's file-system checks (an input file exists, an output's directory is writable) are relaxed:
what a command names is the reader's file, not the docs'; option names, verbs, required options,
numbers and choices are checked as the CLI checks them.
"""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from host.cli.errors import CliError
from host.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

#: Types that look at the file system (host.cli.args and the verbs' own): relaxed to a plain string.
_FS_TYPES = {"existing_file", "output_dir", "_log_file", "calibration_file", "file", "existing_dir", "bundle_dir"}
_PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]*(\.[A-Za-z0-9]+)?$")
_FENCE = re.compile(r"^```(\w*)\s*$")


def _doc_text(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def _rel(path: Path) -> str:
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return path.name


# --- extraction -------------------------------------------------------------------------------

def _shell_commands(line: str, program: str = "thermotouch") -> list[str]:
    """The ``program`` commands of one shell line (comments dropped, ``&&`` / ``;`` chains split, ``sudo`` off)."""
    line = re.sub(r"(^|\s)#.*$", "", line)
    out = []
    for seg in re.split(r"&&|;", line):
        seg = seg.strip().removeprefix("sudo ").strip()
        if seg.startswith(program + " "):
            out.append(seg)
    return out


def commands_in(path: Path, program: str = "thermotouch") -> list[tuple[str, str]]:
    """``(where, command)`` for every ``program`` command shown in ``path``."""
    found: list[tuple[str, str]] = []
    lines = _doc_text(path).splitlines()
    in_fence = False
    lang = ""
    pending = ""
    for n, line in enumerate(lines, 1):
        m = _FENCE.match(line.strip())
        if m:
            in_fence, lang, pending = not in_fence, m.group(1), ""
            continue
        if in_fence:
            if lang not in ("", "sh", "bash", "console", "shell"):
                continue
            text = pending + line.strip()
            if text.endswith("\\"):
                pending = text[:-1].rstrip() + " "
                continue
            pending = ""
            found += [(f"{_rel(path)}:{n}", c) for c in _shell_commands(text.removeprefix("$ "), program)]
            continue
        for span in re.findall(r"`([^`]+)`", line):
            if span.startswith(program + " "):
                found.append((f"{_rel(path)}:{n}", span))
    return found


ALL_COMMANDS = [c for p in DOCS for c in commands_in(p)]
EDGE_COMMANDS = [c for p in DOCS for c in commands_in(p, "thermotouch-edge")]


# --- synopsis expansion -----------------------------------------------------------------------

def _tokens(cmd: str) -> list[str]:
    spaced = re.sub(r"([\[\]()])", r" \1 ", cmd)
    spaced = re.sub(r"\s\|\s", " | ", spaced)
    return [t for t in shlex.split(spaced)]


def _parse_groups(tokens: list[str], i: int = 0, close: str | None = None):
    """Tokens -> a tree: a list of alternatives, each a list of items (str or ('[', tree) / ('(', tree))."""
    alts: list[list] = [[]]
    while i < len(tokens):
        t = tokens[i]
        if t in ("[", "("):
            sub, i = _parse_groups(tokens, i + 1, "]" if t == "[" else ")")
            alts[-1].append((t, sub))
        elif t == close:
            return alts, i
        elif t == "|":
            alts.append([])
        else:
            alts[-1].append(t)
        i += 1
    if close is not None:
        raise ValueError(f"unbalanced {close!r}")
    return alts, i


def _expand(alts, *, optional: bool) -> list[str]:
    """The first alternative, with (``optional``) or without every ``[...]`` group."""
    out: list[str] = []
    for item in alts[0]:
        if isinstance(item, tuple):
            kind, sub = item
            if kind == "[" and not optional:
                continue
            out += _expand(sub, optional=optional)
        elif item in ("...", "…"):
            continue
        else:
            out.append(item.split("|")[0] if "|" in item and not item.startswith("|") else item)
    return out


def _relaxed(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    for action in parser._actions:
        if getattr(action.type, "__name__", None) in _FS_TYPES:
            action.type = str
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _relaxed(sub)
    return parser


@pytest.fixture(scope="module")
def parser():
    # A parser of our own: build_parser() is cached for the CLI, and its file-system types are relaxed here.
    return _relaxed(build_parser.__wrapped__())


def _subparser(parser, argv: list[str]):
    """The innermost (sub)parser ``argv`` selects, for looking up what an option's value must be."""
    p = parser
    for tok in argv:
        sub = next((a for a in p._actions if isinstance(a, argparse._SubParsersAction)), None)
        if sub is None:
            break
        if tok in sub.choices:
            p = sub.choices[tok]
    return p


def _value_for(action: argparse.Action | None) -> str:
    """A value ``action`` accepts, for a placeholder such as ``V``, ``FILE.csv`` or ``NAME``."""
    if action is None:
        return "x"
    if action.choices:
        return str(next(iter(action.choices)))
    for cand in ("1", "0.5", "x.csv", "x"):
        try:
            (action.type or str)(cand)
            return cand
        except (argparse.ArgumentTypeError, ValueError, TypeError):
            continue
    return "x"


def concrete(parser, words: list[str]) -> list[str]:
    """``words`` after ``thermotouch`` with every placeholder replaced by a value its option accepts."""
    argv = words[1:]
    sub = _subparser(parser, argv)
    out: list[str] = []
    action = None
    left = 0
    for tok in argv:
        if tok.startswith("-"):
            name = tok.split("=", 1)[0]
            action = sub._option_string_actions.get(name) or parser._option_string_actions.get(name)
            nargs = None if action is None else action.nargs
            left = 1 if nargs in (None, "?") else (nargs if isinstance(nargs, int) else 99)
            if action is not None and action.nargs == 0:
                left = 0
            out.append(tok)
            continue
        if _PLACEHOLDER.match(tok) or tok.startswith("$"):
            tok = _value_for(action if left > 0 else None)
        out.append(tok)
        left = max(0, left - 1)
    return out


def _variants(cmd: str) -> list[list[str]]:
    tree, _ = _parse_groups(_tokens(cmd))
    full, bare = _expand(tree, optional=True), _expand(tree, optional=False)
    return [full] if full == bare else [full, bare]


# --- tests ------------------------------------------------------------------------------------

def test_the_docs_show_commands():
    assert len(ALL_COMMANDS) >= 30, "the command extraction found too few commands"
    verbs = {_tokens(c)[1] for _, c in ALL_COMMANDS if len(_tokens(c)) > 1}
    for verb in ("measure", "calibrate", "estimate", "objects", "flash", "demo", "history", "keys"):
        assert verb in verbs, f"no `thermotouch {verb}` shown in README.md or docs/"


def _names_a_verb(parser, words: list[str]) -> bool:
    """``thermotouch VERB [ACTION]`` in prose names a verb; it must exist, its required options need not show."""
    if any(w.startswith("-") or _PLACEHOLDER.match(w) or not w.isidentifier() for w in words[1:]):
        return False
    p = parser
    for w in words[1:]:
        sub = next((a for a in p._actions if isinstance(a, argparse._SubParsersAction)), None)
        assert sub is not None and w in sub.choices, f"`{' '.join(words)}`: no verb or action {w!r}"
        p = sub.choices[w]
    return True


@pytest.mark.parametrize(("where", "cmd"), ALL_COMMANDS, ids=[w for w, _ in ALL_COMMANDS])
def test_command_parses(parser, where, cmd):
    if _names_a_verb(parser, _tokens(cmd)):
        return
    for words in _variants(cmd):
        argv = concrete(parser, words)
        try:
            parser.parse_args(argv)
        except CliError as exc:
            pytest.fail(f"{where}: `{cmd}` does not parse as {argv}: {exc}")
        except SystemExit as exc:  # --help / --version print and exit 0
            assert exc.code == 0, f"{where}: `{cmd}` exits {exc.code}"


def test_a_wrong_command_is_caught(parser):
    # The check must be able to fail: an option no verb has, a verb that does not exist, a bad choice.
    for cmd in ("thermotouch measure --port P --no-such-option", "thermotouch frobnicate",
                "thermotouch measure --port P --profile [slow]", "thermotouch estimate --json"):
        with pytest.raises(CliError):
            for words in _variants(cmd):
                parser.parse_args(concrete(parser, words))


def test_synopsis_expansion():
    tree, _ = _parse_groups(_tokens("thermotouch measure (--port PORT | --sim SCENE) [--time S | --profile "
                                    "quick|standard|precise] [--plot FILE.png [--overwrite]] ..."))
    assert _expand(tree, optional=True) == ["thermotouch", "measure", "--port", "PORT", "--time", "S", "--plot",
                                            "FILE.png", "--overwrite"]
    assert _expand(tree, optional=False) == ["thermotouch", "measure", "--port", "PORT"]


def test_commands_are_found_in_fences_and_spans(tmp_path):
    doc = tmp_path / "x.md"
    doc.write_text("Run `thermotouch info --port P` or\n\n```sh\npip install . && thermotouch demo   # go\n"
                   "thermotouch calibrate --record a.csv --reference pmma \\\n    --out cal.json\n```\n"
                   "```python\nthermotouch = 1\n```\n", encoding="utf-8")
    got = [c for _, c in commands_in(doc)]
    assert got == ["thermotouch info --port P", "thermotouch demo",
                   "thermotouch calibrate --record a.csv --reference pmma --out cal.json"]


_BENCH = re.compile(r"\bbench/([A-Za-z0-9_]+\.py)\b")


@pytest.mark.parametrize("path", DOCS, ids=[_rel(p) for p in DOCS])
def test_every_bench_named_exists(path):
    missing = sorted({m for m in _BENCH.findall(_doc_text(path)) if not (ROOT / "bench" / m).is_file()})
    assert not missing, f"{_rel(path)} names benches that do not exist: {missing}"


_MARK = re.compile(r"<!-- ([\w-]+):(begin|end) -->")
_CODE_SPAN = re.compile(r"`[^`]*`")


@pytest.mark.parametrize("path", DOCS, ids=[_rel(p) for p in DOCS])
def test_every_marker_block_is_closed(path):
    open_tag = None
    seen = set()
    for n, line in enumerate(_doc_text(path).splitlines(), 1):
        for tag, kind in _MARK.findall(_CODE_SPAN.sub("", line)):  # a marker quoted in `code` is prose
            where = f"{_rel(path)}:{n}"
            if kind == "begin":
                assert open_tag is None, f"{where}: {tag} begins inside {open_tag}"
                assert tag not in seen, f"{where}: a second {tag} block"
                open_tag = tag
                seen.add(tag)
            else:
                assert open_tag == tag, f"{where}: {tag}:end without its begin"
                open_tag = None
    assert open_tag is None, f"{_rel(path)}: <!-- {open_tag}:begin --> has no end"


def test_each_generated_block_lives_in_one_file():
    where: dict[str, str] = {}
    for path in DOCS:
        for tag, kind in _MARK.findall(_CODE_SPAN.sub("", _doc_text(path))):
            if kind == "begin":
                assert tag not in where, f"block {tag} in both {where.get(tag)} and {_rel(path)}"
                where[tag] = _rel(path)


def test_readme_is_a_front_door():
    text = _doc_text(ROOT / "README.md")
    assert len(text.splitlines()) <= 200
    for mark in ("<!-- main-command -->", "<!-- test-command -->"):
        assert mark in text
    for doc in ("user-guide.md", "science.md", "operations.md", "results.md", "contributing.md"):
        assert f"docs/{doc}" in text, f"README.md does not link docs/{doc}"


@pytest.mark.parametrize(("where", "cmd"), EDGE_COMMANDS, ids=[w for w, _ in EDGE_COMMANDS])
def test_daemon_command_parses(where, cmd):
    from edge.service.main import _parse_args

    for words in _variants(cmd):
        argv = ["x" if _PLACEHOLDER.match(w) else w for w in words[1:]]
        try:
            _parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"{where}: `{cmd}` does not parse (exit {exc.code})")


#: ``[section] key`` or ``section.key`` in code spans, for the daemon's configuration sections.
_CONFIG_REF = re.compile(r"`\[(\w+)\] (\w+)|`(\w+)\.(\w+)`")


def test_configuration_keys_named_exist():
    import tomllib

    example = tomllib.loads((ROOT / "edge" / "service" / "thermotouch-edge.example.toml").read_text())
    # A scene's [board] (world, probe) is named in the same notation: its keys count as known too.
    for scene in (ROOT / "firmware_sim" / "scene" / "shipped").glob("*.toml"):
        for section, keys in tomllib.loads(scene.read_text()).items():
            if isinstance(keys, dict) and section in example:
                example[section] = {**keys, **example[section]}
    named = 0
    for path in DOCS:
        for n, line in enumerate(_doc_text(path).splitlines(), 1):
            for m in _CONFIG_REF.finditer(line):
                section, key = (m.group(1), m.group(2)) if m.group(1) else (m.group(3), m.group(4))
                if section not in example:
                    continue  # a module path such as `edge.recognition`, not a configuration key
                named += 1
                assert key in example[section], f"{_rel(path)}:{n}: [{section}] has no key {key!r}"
    assert named >= 8


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


_LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("path", DOCS, ids=[_rel(p) for p in DOCS])
def test_links_between_the_docs_resolve(path):
    for n, line in enumerate(_doc_text(path).splitlines(), 1):
        for target in _LINK.findall(line):
            if re.match(r"\w+://", target):
                continue
            file_part, _, anchor = target.partition("#")
            dest = (path.parent / file_part).resolve() if file_part else path
            assert dest.exists(), f"{_rel(path)}:{n}: link to {target}: no such file"
            if anchor and dest.suffix == ".md":
                slugs = {_slug(h) for h in re.findall(r"^#+ (.+)$", _doc_text(dest), re.M)}
                assert anchor in slugs, f"{_rel(path)}:{n}: link to {target}: no such heading"


_PATH_REF = re.compile(r"`((?:edge|host|firmware_sim|tests|bench|models)/[\w/.\-]*[\w/])`")
_DOTTED_REF = re.compile(r"`((?:edge|host|firmware_sim)(?:\.\w+)+)`")


def _dotted_exists(ref: str) -> bool:
    """``edge.a.b.Name``: the longest module prefix exists, and the first name after it is in its source."""
    parts = ref.split(".")
    for i in range(len(parts), 0, -1):
        base = ROOT.joinpath(*parts[:i])
        src = base.with_suffix(".py") if base.with_suffix(".py").is_file() else base / "__init__.py"
        if src.is_file():
            rest = parts[i:]
            return not rest or re.search(rf"\b{re.escape(rest[0])}\b", src.read_text(encoding="utf-8")) is not None
    return False


@pytest.mark.parametrize("path", DOCS, ids=[_rel(p) for p in DOCS])
def test_code_the_docs_name_exists(path):
    text = _doc_text(path)
    missing = sorted({m for m in _PATH_REF.findall(text) if not (ROOT / m.rstrip("/")).exists()}
                     | {m for m in _DOTTED_REF.findall(text) if not _dotted_exists(m)})
    assert not missing, f"{_rel(path)} names files or modules that do not exist: {missing}"
