"""The repository stands on its own: no tracked file points at material a user who clones
the project does not have (the developers' folder beside the checkout, the brief and
source texts in it, an absolute path of a developer's machine), no file but the changelog
names an issue number (which means nothing to a user), and every pointer into docs/physics.md
names a section that exists."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PHYSICS = ROOT / "docs" / "physics.md"

# Written in pieces so that this file does not match itself.
SHARED = "sha" + "red"
FORBIDDEN = re.compile("|".join([
    r"\.\./" + SHARED + r"\b",                       # the developers' folder beside the checkout
    SHARED + r"/(spec|seeds|data|hooks)\b",           # ... and what is in it
    r"\bMODEL" + r"\.md\b",                           # the physics brief kept there
    r"\bseeds/",                                      # the source texts kept there, by folder
    r"monograph_lever_" + r"couplings|_paper_" + r"(ru|uk)\b|nonlinear_elastic_coupling_" + r"paper",
    r"(?<![\w.])/(work|root|home)/",                  # absolute paths of a machine
]))


def tracked_files() -> list[str]:
    try:
        done = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files are unknown")
    return [name for name in done.stdout.decode().split("\0") if name]


def mentions(text: str) -> list[str]:
    return [f"{number}: {line.strip()[:120]}" for number, line in enumerate(text.splitlines(), 1)
            if FORBIDDEN.search(line)]


def test_the_pattern_sees_each_kind_of_pointer():
    for line in ["see ../" + SHARED + "/spec/x", "MODEL" + ".md section 2", "se" + "eds/x.txt",
                 "monograph_lever_" + "couplings", "the freewheel_pa" + "per_ru.txt", "/wo" + "rk/main/x",
                 "/ro" + "ot/.pyenv", "/ho" + "me/u/x"]:
        assert mentions(line), line
    for line in ["three load seeds", "shared library", "file:///tmp/x", "docs/physics.md#kinematics"]:
        assert not mentions(line), line


def test_no_tracked_file_points_outside_the_repository():
    """Nothing refers to the developers' own folder or machine: a clone has neither."""
    offenders = []
    for name in tracked_files():
        path = ROOT / name
        if not path.is_file():
            continue
        text = path.read_bytes().decode("utf-8", errors="replace")
        offenders += [f"{name}:{hit}" for hit in mentions(text)]
    assert offenders == []


# An issue number (the word, a number, an optional "#"): the changelog and its measurement
# log in the engineering record are the places where the history of the work lives.
ISSUE_NUMBER = re.compile(r"\bissue" + r" ?#?[0-9]+", re.I)
HISTORY = {"docs/changelog.md", "docs/record/changes-in-detail.md"}


def test_the_issue_pattern_sees_each_spelling():
    for line in ["(iss" + "ue 17)", "Iss" + "ue #3 found", "iss" + "ue12"]:
        assert ISSUE_NUMBER.search(line), line
    for line in ["an issue with the load", "tiss" + "ue 17", "issues show"]:
        assert not ISSUE_NUMBER.search(line), line


def test_no_issue_numbers_outside_the_changelog():
    """Code, tests and user docs say what a thing is and why; its history is the changelog's."""
    offenders = []
    for name in tracked_files():
        path = ROOT / name
        if name in HISTORY or not path.is_file():
            continue
        for number, line in enumerate(path.read_bytes().decode("utf-8", errors="replace").splitlines(), 1):
            if ISSUE_NUMBER.search(line):
                offenders.append(f"{name}:{number}: {line.strip()[:120]}")
    assert offenders == []


# Who built the project is no part of its docs: the words that spoke of the people at work
# beside a measurement, or of who asked for a change.  Written in pieces so that this file
# does not match itself.
BUILDERS = re.compile("|".join([r"other engin" + r"eers", r"engin" + r"eers' work", r"\bthe fil" + r"er\b",
                                r"next engin" + r"eer", r"engin" + r"eering record"]), re.I)


def test_the_builders_pattern_sees_each_wording():
    for line in ["beside seven other engin" + "eers' work", "the fil" + "er's result", "for the next engin" + "eer",
                 "the Engin" + "eering record"]:
        assert BUILDERS.search(line), line
    for line in ["a driveline designer", "the filter", "profiler"]:
        assert not BUILDERS.search(line), line


def test_no_page_speaks_of_who_built_it():
    """The README and the docs speak of the project; the changelog's history is exempt."""
    offenders = []
    for name in tracked_files():
        if not (name == "README.md" or name.startswith("docs/") and name.endswith(".md")) or name in HISTORY:
            continue
        for number, line in enumerate((ROOT / name).read_text(encoding="utf-8").splitlines(), 1):
            if BUILDERS.search(line):
                offenders.append(f"{name}:{number}: {line.strip()[:120]}")
    assert offenders == []


def anchors(markdown: str) -> set[str]:
    """GitHub's anchors of a page's headings: lower case, punctuation dropped, spaces as '-'."""
    out = set()
    for heading in re.findall(r"^#{1,6}\s+(.+?)\s*$", markdown, re.M):
        out.add(re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-"))
    return out


def test_every_pointer_into_the_physics_page_names_a_section():
    known = anchors(PHYSICS.read_text(encoding="utf-8"))
    pointer = re.compile(r"physics\.md#([\w\-]+)")
    broken = []
    for name in tracked_files():
        path = ROOT / name
        if not path.is_file() or path.suffix not in {".py", ".md", ".toml", ".c", ".txt", ""}:
            continue
        for number, line in enumerate(path.read_bytes().decode("utf-8", errors="replace").splitlines(), 1):
            broken += [f"{name}:{number}: #{a}" for a in pointer.findall(line) if a not in known]
    assert broken == []


# The reference pages are generated from the code (build/docs.py, `make docs`); a committed
# page that differs from what the code generates now is stale.
REFERENCE = ROOT / "docs" / "reference"


def stale_pages(committed: Path, generated: Path) -> list[str]:
    """Each page of ``committed`` that differs from ``generated``'s, naming its first
    differing line; pages only one folder has."""
    found = []
    names = sorted({p.name for p in committed.glob("*.md")} | {p.name for p in generated.glob("*.md")})
    for name in names:
        page = f"docs/reference/{name}"
        if not (committed / name).is_file():
            found.append(f"{page}: not committed (generated by `make docs`)")
            continue
        if not (generated / name).is_file():
            found.append(f"{page}: committed, but `make docs` no longer generates it")
            continue
        old = (committed / name).read_text(encoding="utf-8").splitlines()
        new = (generated / name).read_text(encoding="utf-8").splitlines()
        for number, (a, b) in enumerate(zip(old + [None] * len(new), new + [None] * len(old)), 1):
            if a != b:
                found.append(f"{page}:{number}: committed {a!r}, generated now {b!r}")
                break
    return found


def test_a_stale_page_is_named_with_its_first_differing_line(tmp_path):
    committed, generated = tmp_path / "committed", tmp_path / "generated"
    committed.mkdir()
    generated.mkdir()
    for folder in (committed, generated):
        (folder / "same.md").write_text("a\nb\n")
    (committed / "cli.md").write_text("x\nold\nz\n")
    (generated / "cli.md").write_text("x\nnew\nz\n")
    (committed / "gone.md").write_text("a\n")
    (generated / "new.md").write_text("a\n")
    (committed / "short.md").write_text("a\n")
    (generated / "short.md").write_text("a\nb\n")
    assert stale_pages(committed, generated) == [
        "docs/reference/cli.md:2: committed 'old', generated now 'new'",
        "docs/reference/gone.md: committed, but `make docs` no longer generates it",
        "docs/reference/new.md: not committed (generated by `make docs`)",
        "docs/reference/short.md:2: committed None, generated now 'b'"]


def test_the_reference_pages_are_what_the_code_generates(tmp_path):
    """docs/reference/ regenerated into a temporary folder is the committed one, line for
    line: otherwise `make docs` and commit the pages."""

    done = subprocess.run([sys.executable, str(ROOT / "build" / "docs.py"), "--out", str(tmp_path)],
                          cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    stale = stale_pages(REFERENCE, tmp_path)
    assert not stale, "stale reference pages (run `make docs` and commit docs/reference/):\n" + "\n".join(stale)


# A Markdown link: [text](target), its target up to the first space or ')'; code spans and
# fenced blocks are left out (a link there is text, not a link).
LINK = re.compile(r"\[([^\]]*)\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
# a link text that names a file: a path with an extension, in backticks or not
FILE_NAME = re.compile(r"^`?([\w.\-]+/)*[\w\-]+\.(py|md|toml|txt|csv|c|h|json|ipynb|fmu)`?$")
FENCE = re.compile(r"^(```|~~~).*?^\1\s*$", re.M | re.S)
CODE_SPAN = re.compile(r"`[^`\n]*`")


def links(markdown: str) -> list[tuple[int, str, str]]:
    """(line number, text, target) of each link of a page outside code (a link that starts
    inside a code span is text; a code span inside a link's text is its text)."""
    text = FENCE.sub(lambda m: "\n" * m.group(0).count("\n"), markdown)
    found = []
    for number, line in enumerate(text.splitlines(), 1):
        code = [m.span() for m in CODE_SPAN.finditer(line)]
        found += [(number, m.group(1), m.group(2)) for m in LINK.finditer(line)
                  if not any(start < m.start() < end for start, end in code)]
    return found


def _names(text: str, target: Path, here: Path, root: Path) -> bool:
    """Whether a link text that is a path names ``target``: relative to the page, to the
    repository, or as the target's trailing folders and name."""
    return (target in ((here / text).resolve(), (root / text).resolve())
            or target.as_posix().endswith("/" + text.lstrip("./")))


def broken_links(page: Path, root: Path = ROOT) -> list[str]:
    """Each relative link of ``page`` whose file does not exist, whose #anchor names no
    heading of the Markdown page it points into, or whose text names another file than
    the one it opens ([harness/validate.py](../harness/judges/validation.py))."""
    found = []
    for number, label, target in links(page.read_text(encoding="utf-8")):
        if re.match(r"^[a-z][a-z0-9+.\-]*:", target, re.I):        # http:, https:, mailto: ...
            continue
        path, _, anchor = target.partition("#")
        into = (page.parent / path).resolve() if path else page
        where = f"{page.relative_to(root)}:{number}: {target}"
        if not into.exists():
            found.append(f"{where} (no such file)")
        elif anchor and into.suffix == ".md" and anchor not in anchors(into.read_text(encoding="utf-8")):
            found.append(f"{where} (no such heading)")
        elif FILE_NAME.match(label.strip()) and not _names(label.strip().strip("`"), into, page.parent, root):
            found.append(f"{where} (its text names {label.strip()})")
    return found


def test_a_broken_link_is_named_and_a_good_one_is_not(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("# A page\n\n## The part\n")
    page = tmp_path / "README.md"
    page.write_text("[ok](docs/a.md) [ok](docs/a.md#the-part) [ok](#top) [web](https://x.org/y)\n"
                    "# Top\n`[code](nowhere.md)`\n```\n[fenced](nowhere.md)\n```\n"
                    "[gone](docs/b.md) [no part](docs/a.md#no-part) [dir](docs/)\n"
                    "[docs/a.md](docs/a.md) [`a.md`](docs/a.md) [docs/c.md](docs/a.md)\n")
    assert broken_links(page, tmp_path) == ["README.md:7: docs/b.md (no such file)",
                                            "README.md:7: docs/a.md#no-part (no such heading)",
                                            "README.md:8: docs/a.md (its text names docs/c.md)"]


def test_every_relative_link_in_the_readme_and_the_docs_resolves():
    """A link a user follows from the README or a docs page opens a file that exists, at a
    heading that exists."""
    pages = [ROOT / name for name in tracked_files()
             if name == "README.md" or name.startswith("docs/") and name.endswith(".md")]
    broken = [found for page in pages if page.is_file() for found in broken_links(page)]
    assert broken == []


# The guide's commands: each `lever COMMAND --option` a guide page shows is one the command
# line has (a renamed command or option would leave the guide teaching what fails).
GUIDE = ROOT / "docs" / "guide"
LEVER_CALL = re.compile(r"(?:^|[\s`/])lever\s+([a-z][\w\-]*)((?:\s+[^\s`#|]+)*)")


def lever_calls(markdown: str) -> list[tuple[str, list[str]]]:
    """(command, [its --options]) of each `lever ...` call on a page, in code or prose."""
    calls = []
    for line in markdown.splitlines():
        for command, rest in LEVER_CALL.findall(line):
            options = [word.split("=")[0] for word in rest.split() if word.startswith("--")]
            calls.append((command, options))
    return calls


def unknown_calls(markdown: str, group) -> list[str]:
    """Each command or option of ``lever_calls`` that ``group`` (the click group) lacks."""
    found = []
    for command, options in lever_calls(markdown):
        known = group.commands.get(command)
        if known is None:
            found.append(f"lever {command}: no such command")
            continue
        names = {name for param in known.params for name in param.opts + param.secondary_opts}
        found += [f"lever {command} {option}: no such option" for option in options if option not in names]
    return found


def test_an_unknown_command_or_option_of_the_guide_is_named():
    import click

    @click.group()
    def group():
        pass

    @group.command()
    @click.option("--stop")
    def run(stop):
        pass

    page = "```sh\n.venv/bin/lever run kavz685 --stop 3 --sotp 4\nlever runn x\n```\nthen `lever run --stop=2`\n"
    assert unknown_calls(page, group) == ["lever run --sotp: no such option", "lever runn: no such command"]


def test_every_command_and_option_the_guide_shows_exists():
    from harness.cli import main

    pages = sorted(GUIDE.glob("*.md"))
    assert pages, "no guide pages"
    found = [f"{page.name}: {problem}" for page in pages
             for problem in unknown_calls(page.read_text(encoding="utf-8"), main)]
    assert found == []
