"""The README and docs/ stay true: links resolve (between pages, to code files, and to a heading's
anchor), the README stays short, no page grows past a screenful of screens, every ``clothsim ...``
command the pages quote (in a code block or inline) parses with the real parser, and every
``python tests/tools/X.py`` they quote exists and answers ``--help``. Nothing here runs a
simulation: the commands are parsed, not run, so the whole file takes a few seconds."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import runpy
import shlex
import sys
from pathlib import Path

import pytest

from clothsim.cli import build_parser
from clothsim.scene import bundled_scene_names, load_scene

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
DOCS = REPO / "docs"
PAGES = [README, *sorted(DOCS.rglob("*.md"))]
README_MAX_LINES = 200
#: No docs page is longer: a longer one is split by topic (a reference page and its history).
PAGE_MAX_LINES = 500

#: History pages record commands as they were run: their commands must name a command and flags
#: that exist, but may leave out what the figure did not depend on (an output file, say).
HISTORY = DOCS / "history"

FENCE = re.compile(r"^(```|~~~)")
LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
INLINE_CODE = re.compile(r"`[^`]*`")


def prose_lines(text: str, keep_code: bool = False) -> list[str]:
    """The lines outside fenced code blocks, with inline code removed unless ``keep_code``."""
    out, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            out.append(line if keep_code else INLINE_CODE.sub("", line))
    return out


def code_blocks(text: str) -> list[tuple[str, list[str]]]:
    """Every fenced block as (its info string, its lines)."""
    blocks, current, info = [], None, ""
    for line in text.splitlines():
        m = FENCE.match(line.strip())
        if m and current is None:
            current, info = [], line.strip()[3:].strip()
        elif m:
            blocks.append((info, current))
            current = None
        elif current is not None:
            current.append(line)
    return blocks


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link's text only
    text = text.replace("`", "").strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every anchor a page's headings give, duplicates numbered as GitHub numbers them."""
    seen: dict[str, int] = {}
    out = set()
    for line in prose_lines(page.read_text(encoding="utf-8"), keep_code=True):
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        base = slug(m.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(page: Path) -> list[str]:
    found = []
    for line in prose_lines(page.read_text(encoding="utf-8")):
        found.extend(LINK.findall(line))
    return found


def test_readme_is_short() -> None:
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= README_MAX_LINES, f"README.md has {n} lines; at most {README_MAX_LINES} (details go to docs/)"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_relative_links_resolve(page: Path) -> None:
    problems = []
    for target in links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        path_part, _, anchor = target.partition("#")
        if path_part.startswith("/"):
            problems.append(f"{target}: absolute path (links must be relative)")
            continue
        dest = (page.parent / path_part).resolve() if path_part else page
        if not dest.exists():
            problems.append(f"{target}: no such file")
            continue
        if anchor:
            if dest.suffix != ".md":
                problems.append(f"{target}: an anchor into a file that is not Markdown")
            elif anchor not in anchors(dest):
                problems.append(f"{target}: no heading with anchor #{anchor} in {dest.name}")
    assert not problems, f"{page.relative_to(REPO)}:\n" + "\n".join(problems)


def test_every_docs_page_has_a_contents_list() -> None:
    for page in sorted(DOCS.glob("*.md")):
        own = [t for t in links(page) if t.startswith("#")]
        assert len(own) >= 2, f"{page.name}: no contents list (links to its own sections) at the top"


def test_readme_images_are_small_pngs() -> None:
    for target in links(README):
        if target.endswith(".png"):
            size = (README.parent / target).stat().st_size
            assert size < 300_000, f"{target}: {size} bytes; keep a README image under 300 KB"


def test_readme_quick_start_is_what_ci_runs() -> None:
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    test_command = ci[-1].strip()
    assert test_command.endswith("python -m pytest"), test_command
    readme = README.read_text(encoding="utf-8").splitlines()
    assert test_command in readme, "the README's test command must be exactly the one .ci/run runs"
    assert ("python3 -m venv .venv && .venv/bin/pip install . && "
            ".venv/bin/clothsim render pinned2 --shader phong -o cloth.png") in readme


def test_readme_minimal_scene_loads(tmp_path: Path) -> None:
    scenes = [lines for info, lines in code_blocks(README.read_text(encoding="utf-8")) if info == "json"]
    assert scenes, "the README shows a minimal scene"
    path = tmp_path / "drop.json"
    path.write_text("\n".join(scenes[0]), encoding="utf-8")
    json.loads(path.read_text(encoding="utf-8"))
    scene = load_scene(path)
    assert scene.spheres and scene.planes


def test_readme_names_every_bundled_scene() -> None:
    text = README.read_text(encoding="utf-8")
    missing = [name for name in bundled_scene_names() if f"`{name}`" not in text]
    assert not missing, f"README.md does not name the bundled scenes {missing}"


def test_the_help_names_every_bundled_scene() -> None:
    from clothsim.cli import EPILOG

    listed = EPILOG.split("bundled scene:", 1)[1].split(".", 1)[0]
    names = {word.strip(" ,()\n") for word in listed.replace("(the course's)", "").split(",")}
    assert names == set(bundled_scene_names())


def commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    """(command path, parser) of every command and sub-command."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield path + (name,), sub
                yield from commands(sub, path + (name,))


def is_group(parser: argparse.ArgumentParser) -> bool:
    return any(isinstance(a, argparse._SubParsersAction) for a in parser._actions)


def command_lines(text: str) -> list[str]:
    """Every `clothsim ...` command shown in a code block, continuation lines joined, comments off."""
    out = []
    for _, lines in code_blocks(text):
        current = None
        for line in lines:
            body = re.sub(r"^\$\s+|^\.venv/bin/", "", line)
            if body.startswith("clothsim "):
                if current is not None:
                    out.append(current)
                current = body
            elif current is not None and line[:1].isspace() and line.strip():
                current += " " + line.strip()
            else:
                if current is not None:
                    out.append(current)
                current = None
        if current is not None:
            out.append(current)
    return [re.split(r"\s#\s", c)[0] for c in out]


def resolve(words: list[str], known: dict[tuple[str, ...], argparse.ArgumentParser]) -> tuple[str, ...]:
    path: tuple[str, ...] = ()
    for word in words:
        if path + (word,) in known:
            path += (word,)
        else:
            break
    return path


def test_commands_shown_in_the_docs_take_the_flags_shown() -> None:
    known = dict(commands(build_parser()))
    problems = []
    for page in PAGES:
        for line in command_lines(page.read_text(encoding="utf-8")):
            path = resolve(line.split()[1:], known)
            if not path:
                problems.append(f"{page.name}: {line!r}: no such command")
                continue
            options = {o for a in known[path]._actions for o in a.option_strings}
            for flag in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", line):
                if flag not in options:
                    problems.append(f"{page.name}: clothsim {' '.join(path)} has no {flag}")
    assert not problems, "\n".join(problems)


def test_cli_synopsis_lists_every_command_and_flag() -> None:
    text = (DOCS / "cli.md").read_text(encoding="utf-8")
    synopsis = text.split("## Synopsis", 1)[1]
    entries = {}
    known = dict(commands(build_parser()))
    for line in command_lines(synopsis.split("\n## ", 1)[0]):
        entries.setdefault(resolve(line.split()[1:], known), line)
    problems = []
    for path, parser in known.items():
        if is_group(parser):
            continue
        entry = entries.get(path)
        if entry is None:
            problems.append(f"clothsim {' '.join(path)}: not in the synopsis")
            continue
        for action in parser._actions:
            names = [o for o in action.option_strings if o not in ("-h", "--help")]
            if names and not any(re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", entry) for o in names):
                problems.append(f"clothsim {' '.join(path)}: {'/'.join(names)} not in the synopsis")
    assert not problems, "docs/cli.md:\n" + "\n".join(problems)


def test_readme_and_performance_name_every_command() -> None:
    known = dict(commands(build_parser()))
    readme = README.read_text(encoding="utf-8")
    performance = (DOCS / "performance.md").read_text(encoding="utf-8")
    missing = [f"clothsim {p[0]}" for p in known if len(p) == 1 and f"clothsim {p[0]}" not in readme]
    missing += [f"performance.md: clothsim bench {p[1]}" for p in known
                if len(p) == 2 and p[0] == "bench" and f"clothsim bench {p[1]}" not in performance]
    assert not missing, missing


def test_no_docs_page_is_longer_than_its_limit() -> None:
    long = {str(p.relative_to(REPO)): n for p in PAGES if p.parent != REPO
            and (n := len(p.read_text(encoding="utf-8").splitlines())) > PAGE_MAX_LINES}
    assert not long, f"pages over {PAGE_MAX_LINES} lines (split them by topic): {long}"


#: What a quoted command may start with before ``clothsim``: environment settings, a prompt, the
#: checkout's virtual environment.
_PREFIX = re.compile(r"^(?:\$\s+)?(?:[A-Z_][A-Z0-9_]*=\S*\s+)*(?:\.venv/bin/)?(?=clothsim\s|python3?\s)")
#: Shell words that end a command (a redirection, a pipe, the next command, a comment).
_SHELL_END = {">", ">>", "|", "&&", ";", "#", "2>", "&"}


def quoted_commands(text: str) -> list[tuple[str, bool]]:
    """Every command a page quotes, as (command, whether it shows an error on purpose): each
    command line of a code block (where a block prompts with ``$ ``, only the prompted lines;
    continuation lines joined) and each inline code span, that starts (after environment
    settings, a prompt or ``.venv/bin/``) with ``clothsim`` or ``python``. A prompted line whose
    output in the block is ``clothsim: error: ...`` shows an error on purpose."""
    found: list[tuple[str, bool]] = []
    for _, lines in code_blocks(text):
        prompted = any(line.startswith("$ ") for line in lines)
        joined: list[tuple[str, bool]] = []
        current = ""
        for k, line in enumerate(lines):
            if prompted and not current and not line.startswith("$ "):
                continue
            current = (current + " " + line.strip()) if current else line
            if current.endswith("\\"):
                current = current[:-1]
                continue
            following = lines[k + 1] if k + 1 < len(lines) else ""
            joined.append((current, following.startswith("clothsim: error:")))
            current = ""
        found += joined
    # an inline span may run over a line break: the prose is read as one text
    prose = "\n".join(prose_lines(text, keep_code=True))
    found += [(" ".join(m.group(0)[1:-1].split()), False) for m in re.finditer(r"`[^`]+`", prose)]
    commands = []
    for candidate, error in found:
        m = _PREFIX.match(candidate.strip())
        if m:
            commands.append((candidate.strip()[m.end():], error))
    return commands


def command_words(command: str) -> list[str] | None:
    """The words of a quoted command up to the first shell word that ends it; None where a word is
    a placeholder (``SCENE``, ``N``, ``[--flag]``, ``a|b``, ``...``): such a line shows a form,
    not a command, and its flags are checked by :func:`test_commands_shown_in_the_docs_take_the_flags_shown`."""
    try:
        words = shlex.split(command, comments=True)
    except ValueError:
        return None
    out = []
    for word in words:
        if word in _SHELL_END or word.startswith((">", "2>")):
            break
        if re.search(r"[\[\]|<>{}]|\.\.\.", word) or re.fullmatch(r"[A-Z][A-Z0-9_]*(?:=\S*)?", word):
            return None
        out.append(word)
    return out


def _parses(parser: argparse.ArgumentParser, words: list[str]) -> str | None:
    """None when ``words`` parse as a command line of ``parser``, else argparse's message. The
    parser only parses: no command runs."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            parser.parse_args(words)
    except SystemExit as stop:
        if stop.code not in (0, None):
            return err.getvalue().strip().splitlines()[-1] if err.getvalue().strip() else f"exit {stop.code}"
    return None


def test_every_quoted_clothsim_command_parses() -> None:
    # A command quoted as reproducing a figure must still be one the command line takes: each is
    # parsed by the real parser, in this process (nothing runs), flags, choices and types included.
    # Not checked: a command's bare name (`clothsim render`) or a flag named on its own
    # (`clothsim compile --jobs`), which name things rather than run them, and the error examples.
    parser = build_parser()
    known = dict(commands(parser))
    for sub in (parser, *known.values()):
        sub.allow_abbrev = False  # a flag quoted must be the flag's whole name, not a prefix of it
    problems, checked = [], 0
    for page in PAGES:
        history = HISTORY in page.parents
        for command, error in quoted_commands(page.read_text(encoding="utf-8")):
            words = command_words(command)
            if error or words is None or words[0] != "clothsim":
                continue
            path = resolve(words[1:], known)
            rest = words[1 + len(path):]
            if not path or not rest or (len(rest) == 1 and rest[0].startswith("--")):
                continue
            checked += 1
            why = _parses(parser, words[1:])
            if why is not None and history and "are required" in why:
                continue  # as it was run; what it left out is not what it measured
            if why is not None:
                problems.append(f"{page.relative_to(REPO)}: {command!r}: {why}")
    assert checked > 80, f"only {checked} quoted commands found: the extraction is broken"
    assert not problems, "\n".join(problems)


def test_every_quoted_tool_exists_and_answers_help() -> None:
    # `python tests/tools/X.py ...` quoted in the docs: the file is there and its own parser
    # answers --help (run in this process, with its module-level code; it must not start work).
    tools = set()
    for page in PAGES:
        for command, _ in quoted_commands(page.read_text(encoding="utf-8")):
            words = command_words(command) or command.split()
            if len(words) >= 2 and words[0] in ("python", "python3") and words[1].startswith("tests/tools/"):
                tools.add(words[1])
    assert "tests/tools/bitid.py" in tools, sorted(tools)
    problems = []
    for tool in sorted(tools):
        path = REPO / tool
        if not path.is_file():
            problems.append(f"{tool}: no such file")
            continue
        out = io.StringIO()
        argv = sys.argv
        sys.argv = [str(path), "--help"]
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
                runpy.run_path(str(path), run_name="__main__")
            problems.append(f"{tool} --help: returned without exiting (it did not parse its arguments)")
        except SystemExit as stop:
            if stop.code not in (0, None) or "usage:" not in out.getvalue():
                problems.append(f"{tool} --help: exit {stop.code}, no usage printed")
        finally:
            sys.argv = argv
    assert not problems, "\n".join(problems)
