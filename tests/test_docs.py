"""The README and docs/ stay true: links resolve, the README stays short, and the commands and
flags they show are the ones the command line has."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import pytest

from clothsim.cli import build_parser
from clothsim.scene import bundled_scene_names, load_scene

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
DOCS = REPO / "docs"
PAGES = [README, *sorted(DOCS.glob("*.md"))]
README_MAX_LINES = 200

# Pages the README links to that are written on another line of work; once a page exists it is
# checked like every other (its anchors included). Remove a name once its page has landed.

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
