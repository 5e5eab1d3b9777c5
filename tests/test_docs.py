"""The project's Markdown documents hold together: links land, tables render.

The README and the pages under ``docs/`` link to each other's sections by GitHub's heading
anchors; a section moved or renamed leaves links that lead nowhere, which nothing else notices.
A ``|`` inside a table cell (in ``|G'|``, say) splits the cell unless escaped, and GitHub then
drops the row's tail. The model's docstring example, what ``help(asnn.ASNN)`` shows a newcomer,
runs: pytest collects no doctests, and an example nothing runs rots unseen.
"""

from __future__ import annotations

import doctest
import functools
import io
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", ROOT / "CONTRIBUTING.md", *sorted((ROOT / "docs").glob("*.md")),
             ROOT / "examples" / "README.md"]
_LINK = re.compile(r"\[(?:[^\]]*)\]\(([^)\s]+)\)")


def heading_anchor(heading: str) -> str:
    """GitHub's anchor for a heading's text: lower case, punctuation dropped, spaces to dashes."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def prose_lines(text: str) -> list[str]:
    """The document's lines with fenced code blocks (fences included) blanked, so that nothing
    in code is read as a heading, a link or a table, and line numbers stay as they are."""
    lines, fenced = [], False
    for line in text.splitlines():
        fence = line.startswith("```")
        fenced ^= fence
        lines.append("" if fence or fenced else line)
    return lines


def anchors(text: str) -> set[str]:
    """The anchors of a document's headings (outside code blocks), repeated ones numbered."""
    found, seen = set(), {}
    for line in prose_lines(text):
        match = re.match(r"#{1,6}\s+(.*)", line)
        if match:
            anchor = heading_anchor(match.group(1))
            count = seen.get(anchor, 0)
            seen[anchor] = count + 1
            found.add(anchor if count == 0 else f"{anchor}-{count}")
    return found


@functools.cache
def _anchors_of(path: Path) -> frozenset[str]:
    return frozenset(anchors(path.read_text()))


def broken_links(document: Path) -> list[str]:
    """The relative links of a document whose file or section does not exist."""
    broken = []
    for target in _LINK.findall("\n".join(prose_lines(document.read_text()))):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto: ...
            continue
        path, _, anchor = target.partition("#")
        destination = (document.parent / path).resolve() if path else document
        if not destination.exists():
            broken.append(f"{target} (no such file)")
        elif anchor and destination.suffix == ".md" and anchor not in _anchors_of(destination):
            broken.append(f"{target} (no such section)")
    return broken


def ragged_rows(document: Path) -> list[str]:
    """Table rows with more or fewer unescaped ``|`` than their table's header row."""
    ragged, header = [], None
    for number, line in enumerate(prose_lines(document.read_text()), 1):
        if not line.startswith("|"):
            header = None
            continue
        bars = len(re.findall(r"(?<!\\)\|", line))
        if header is None:
            header = bars
        elif bars != header:
            ragged.append(f"line {number}: {line[:60]}")
    return ragged


def test_anchors_follow_githubs_rule():
    assert heading_anchor("Labelled suite of generated scenes (`asnn eval --synthetic`, "
                          "version 6)") == \
        "labelled-suite-of-generated-scenes-asnn-eval---synthetic-version-6"
    assert anchors("# A\n```\n# not a heading\n```\n## A\n") == {"a", "a-1"}


def test_the_checks_find_what_they_look_for(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title\n[ok](#title) [gone](#nothing) [file](missing.md)\n\n"
                    "| a | b |\n| --- | --- |\n| `\\|x\\|` | 1 |\n| `|x|` | 1 |\n")
    assert broken_links(page) == ["#nothing (no such section)", "missing.md (no such file)"]
    assert ragged_rows(page) == ["line 7: | `|x|` | 1 |"]


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_links_land(document):
    assert broken_links(document) == []


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_table_rows_have_their_headers_cells(document):
    assert ragged_rows(document) == []


_POINTER = re.compile(r"""(README|CONTRIBUTING|docs/[\w-]+)(?:\.md)?, ["']([^"']+)["']""")


def headings(text: str) -> list[str]:
    """The text of a document's headings (outside code blocks)."""
    return [m.group(1) for line in prose_lines(text) for m in [re.match(r"#{1,6}\s+(.*)", line)]
            if m]


def lost_pointers(source: str) -> list[str]:
    """The pointers into the documents in a module's text (``README, "Ablation"``,
    ``docs/operations.md, "Hostile input"``; line breaks and comment marks between their words
    ignored) whose words begin no heading of that document."""
    flat = re.sub(r"\s*\n\s*(?:#\s*)?", " ", source)
    lost = []
    for document, words in _POINTER.findall(flat):
        path = ROOT / (document if document.startswith("docs/") else document.upper()
                       ).replace(".md", "")
        path = path.with_suffix(".md")
        titles = [re.sub(r"[`*]", "", h).lower() for h in headings(path.read_text())] \
            if path.exists() else []
        if not any(title.startswith(words.lower()) for title in titles):
            lost.append(f"{document}, {words!r}")
    return lost


def test_pointers_from_the_code_name_sections_that_exist():
    """What the code tells a user to read (a warning's "docs/evaluation.md, 'At half the frame
    rate'") is there: a section renamed or moved leaves the pointer leading nowhere."""
    assert lost_pointers('x = 1  # (README, "Nowhere at all")') == ["README, 'Nowhere at all'"]
    lost = {str(path.relative_to(ROOT)): found
            for folder in ("asnn", "service", "clients", "cli", "examples")
            for path in sorted((ROOT / folder).rglob("*.py"))
            for found in [lost_pointers(path.read_text())] if found}
    assert lost == {}


def test_the_documents_the_help_names_ship_with_the_sources_and_the_help_says_where():
    """A new user's trial: the commands' help names docs/*.md, which a wheel does not install;
    each one named is in the repository and grafted into the source distribution, and
    ``asnn --help`` says where they are."""
    from cli.main import build_parser

    parser = build_parser()
    helps = [parser.format_help(), *(sub.format_help() for sub in parser.commands.values())]
    named = set(re.findall(r"docs/[\w.-]+\.md", " ".join(" ".join(helps).split())))
    assert named, "no help text names a document: the check looks at nothing"
    assert sorted(name for name in named if not (ROOT / name).is_file()) == []
    assert "graft docs" in (ROOT / "MANIFEST.in").read_text().splitlines()
    assert "source distribution" in " ".join(parser.format_help().split())


def test_citation_file_passes_its_schema_and_names_this_version():
    """CITATION.cff is what GitHub's "Cite this repository" and Zenodo read: a file the format's
    schema refuses is ignored by them without a word, and a version left behind at a release
    names the wrong figures."""
    import subprocess
    import tomllib

    from test_compose import check_jsonschema

    citation = ROOT / "CITATION.cff"
    result = subprocess.run([*check_jsonschema(), "--builtin-schema",
                             "vendor.citation-file-format", str(citation)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    fields = dict(re.findall(r"^(version|license): (\S+)$", citation.read_text(), re.M))
    assert fields == {"version": project["version"], "license": project["license"]}
    # the package index names the same authors, and the Python it was tested on (its floor)
    cited = re.search(r"^authors:\n((?:  - name: .*\n)+)", citation.read_text(), re.M)
    assert cited and re.findall(r'name: "(.*)"', cited.group(1)) == [
        a["name"] for a in project["authors"]]
    floor = project["requires-python"].removeprefix(">=")
    assert f"Programming Language :: Python :: {floor}" in project["classifiers"]
    # and asnn --version names the same version (what a citation or a bug report names)
    import subprocess
    import sys

    import asnn

    assert asnn.__version__ == project["version"]
    shown = subprocess.run([sys.executable, "-m", "cli.main", "--version"], cwd=ROOT,
                           capture_output=True, text=True, timeout=60)
    assert shown.returncode == 0 and shown.stdout == f"asnn {project['version']}\n"


def run_examples(obj) -> tuple[int, str]:
    """Run the examples of an object's own docstring (not its members'): how many ran, and
    doctest's report of those that failed ("" where none did)."""
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    report = io.StringIO()
    for test in doctest.DocTestFinder(recurse=False).find(obj, obj.__name__, globs={}):
        runner.run(test, out=report.write)
    return runner.tries, report.getvalue()


def test_the_example_runner_reports_a_wrong_example():
    class Wrong:
        """An example that fails.

        >>> 1 + 1
        3
        """

    tries, report = run_examples(Wrong)
    assert tries == 1 and "Expected:\n    3\nGot:\n    2" in report


def test_the_models_docstring_example_runs():
    """``help(asnn.ASNN)``'s example (a generated looming scene stepped, its warning and
    target read) runs as written."""
    from asnn import ASNN

    tries, report = run_examples(ASNN)
    assert tries >= 8, "the example lost its steps"
    assert report == ""


def field_tables(text: str, heading: str) -> dict[str, dict[str, bool]]:
    """The field tables of a section: for each ``**Name**`` before a table, its fields (the
    first column's backquoted names) and whether the table says they are required."""
    lines = prose_lines(text)
    start = next((i for i, line in enumerate(lines) if line.strip() == heading), None)
    assert start is not None, f"no section {heading!r}"
    tables, name = {}, None
    for line in lines[start + 1:]:
        if line.startswith("## "):
            break
        label = re.match(r"\*\*(\w+)\*\*", line)
        if label:
            name = label.group(1)
            tables[name] = {}
        elif name and line.startswith("| `"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
            for field in re.findall(r"`(\w+)`", cells[0]):
                tables[name][field] = cells[2] == "yes"
    return tables


def test_contract_field_tables_are_the_wire_formats():
    """docs/contract.md's Frame, Response and Target tables, what a client written without this
    package reads, name every field of ``service.messages``' models, and a field they call
    required is refused when missing (one they call optional is not); an optional field without
    a value is left out of the map, as the page says."""
    import msgpack

    from service.messages import (Frame, MessageError, Response, TargetMsg, decode_frame,
                                  decode_response, encode)

    tables = field_tables((ROOT / "docs" / "contract.md").read_text(),
                          "## Frame and Response, field by field")
    models = {"Frame": Frame, "Response": Response, "Target": TargetMsg}
    assert {name: set(table) for name, table in tables.items()} == \
        {name: set(model.model_fields) for name, model in models.items()}

    target = dict(x=1.0, y=2.0, direction=0.5, energy=0.1, pixels=3, id=7, expansion=2.0,
                  ttc=0.5, offset=0.1, approaching=True)
    response = dict(v=1, robot="r1", seq=4, stamp=1.5, model="asnn", preset="robust", u=3.0,
                    out=0.6, spikes=1, spike_rate=10.0, collision=True, targets=[target],
                    worker="w1", latency_ms=2.0, dropped=0, model_ms=1.0, stream_frames=5)
    frame = dict(v=1, seq=0, stamp=0.5, width=2, height=1, format="gray8", data=b"\0\0")
    messages = {"Frame": (frame, decode_frame, lambda m: m),
                "Response": (response, decode_response, lambda m: m),
                "Target": (target, decode_response, lambda m: {**response, "targets": [m]})}
    for name, (message, decode, wrap) in messages.items():
        decode(msgpack.packb(wrap(message)))
        for field, required in tables[name].items():
            cut = msgpack.packb(wrap({k: v for k, v in message.items() if k != field}))
            if required:
                with pytest.raises(MessageError) as refused:
                    decode(cut)
                # a target's missing field is the response's ill-typed one
                assert refused.value.reason == ("invalid-field" if name == "Target"
                                                else "missing-field"), (name, field)
            else:
                decode(cut)
    bare = Response(**{**response, "model_ms": None, "stream_frames": None,
                       "targets": [TargetMsg(x=1.0, y=2.0, direction=0.0, energy=0.0, pixels=1)]})
    sent = msgpack.unpackb(encode(bare))
    assert "model_ms" not in sent and "stream_frames" not in sent
    assert set(sent["targets"][0]) == {"x", "y", "direction", "energy", "pixels"}
