"""docs/results/ holds what the docs cite, and nothing else: every docs/results path that README.md and
docs/*.md cite exists, every file under docs/results is cited (by name, or inside a cited run folder), and the
tree stays small (one summary per screen, raw outputs regenerated from the docs' commands). Plain text and
JSON only: no JAX.

A citation is `docs/results/PATH` anywhere; `results/PATH` in docs/*.md (links relative to docs/);
`habituation_screens/...` and `rescored/...` without the prefix; a backticked `FOLDER/...` or `FOLDER*` whose
FOLDER is a run folder of docs/results (the docs name a screen by its folder once its section has given the
prefix; the first of docs/results/, habituation_screens/, rescored/ that holds it); and `$R/PATH` in a code block that sets `R=docs/results/...`. Brace forms (`{a,b}.json`) expand,
globs must match, and `<placeholder>` cuts the path there. A cited folder must hold a file; it covers the
files in it, except the three collections (docs/results/, habituation_screens/, rescored/), whose files are
cited through their own folders.
"""

import fnmatch
import glob
import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"
COLLECTIONS = {"", "habituation_screens", "rescored"}
MAX_FILES = 300
MAX_BYTES = 5_000_000

_PATH = r"[A-Za-z0-9_.{},*<>/-]*"


def _docs() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _other_sources() -> list[Path]:
    """Code and configs that cite a result (a comment, a constant): they count for coverage too."""
    files = [*sorted((ROOT / "notebooks").glob("*.ipynb")), *sorted((ROOT / "scripts").glob("*.py")),
             *sorted((ROOT / "mjx_protamer").rglob("*.py")), *sorted((ROOT / "configs").glob("*.yaml")),
             *sorted((ROOT / "tests").rglob("*.py"))]
    return [f for f in files if f.resolve() != Path(__file__).resolve()]


def _expand_braces(s: str) -> list[str]:
    m = re.search(r"\{([^{}]*)\}", s)
    if not m:
        return [s]
    return [x for alt in m.group(1).split(",") for x in _expand_braces(s[:m.start()] + alt + s[m.end():])]


def _clean(token: str) -> str:
    """The path part of a token: cut at a placeholder, without trailing punctuation."""
    return token.split("<")[0].rstrip(".,:;")


def _run_folders() -> set[str]:
    """Folder names a backticked bare citation may start with: the run folders of docs/results."""
    names = set()
    for base in COLLECTIONS:
        d = RESULTS / base
        names |= {p.name for p in d.iterdir() if p.is_dir() and p.name not in COLLECTIONS}
    return names


def citations(path: Path) -> list[str]:
    """The docs/results-relative paths (possibly with braces or globs) that one file cites."""
    text = path.read_text(errors="replace")
    found = [m.group(1) for m in re.finditer(r"docs/results/(" + _PATH + ")", text)]
    if path.parent == ROOT / "docs" and path.suffix == ".md":
        found += [m.group(1) for m in re.finditer(r"(?<![\w/.$-])results/(" + _PATH + ")", text)]
    found += [m.group(1) for m in re.finditer(r"(?<![\w/.$-])((?:habituation_screens|rescored)/" + _PATH + ")", text)]
    for block in re.findall(r"```.*?```", text, flags=re.S):
        r = re.search(r"\bR=docs/results/(" + _PATH + r")", block)
        if r:
            found += [r.group(1).rstrip("/") + "/" + m.group(1) for m in re.finditer(r"\$R/(" + _PATH + ")", block)]
    if path.suffix == ".md":
        folders = _run_folders()
        for m in re.finditer(r"`([A-Za-z0-9_.{},*-]+(?:/[A-Za-z0-9_.{},*-]*)*)`", text):
            token = m.group(1)
            first = token.split("/")[0]
            in_folder = "/" in token and any(fnmatch.fnmatchcase(f, first) for f in folders)
            if in_folder or "/" not in token and token.endswith("*"):
                base = next((b for b in ("", "habituation_screens", "rescored")
                             if glob.glob(str(RESULTS / b / first))), None)
                if base is not None:
                    found.append(f"{base}/{token}" if base else token)
    return [_clean(t) for t in found]


def _resolve(cited: str) -> list[tuple[str, list[Path]]]:
    """(pattern, what it names) for each brace alternative; an empty list means it names nothing."""
    out = []
    for pattern in _expand_braces(cited):
        pattern = pattern.rstrip("/")
        if any(c in pattern for c in "*?"):
            hits = [Path(p) for p in sorted(glob.glob(str(RESULTS / pattern)))]
        else:
            hits = [RESULTS / pattern] if (RESULTS / pattern).exists() else []
        out.append((pattern, hits))
    return out


def _files() -> list[Path]:
    return sorted(p for p in RESULTS.rglob("*") if p.is_file())


def test_every_cited_results_path_exists():
    missing = []
    for doc in _docs():
        for cited in citations(doc):
            for pattern, hits in _resolve(cited):
                empty = [h for h in hits if h.is_dir() and not any(p.is_file() for p in h.rglob("*"))]
                if not hits or empty:
                    missing.append(f"{doc.relative_to(ROOT)}: docs/results/{pattern}")
    assert not missing, "cited but missing (or an empty folder):\n" + "\n".join(sorted(set(missing)))


def test_results_tree_is_small():
    files = _files()
    size = sum(p.stat().st_size for p in files)
    assert len(files) < MAX_FILES, f"docs/results holds {len(files)} files (under {MAX_FILES} wanted)"
    assert size < MAX_BYTES, f"docs/results holds {size:,} bytes (under {MAX_BYTES:,} wanted)"


def test_every_results_file_is_cited():
    files, folders = set(), set()
    for source in _docs() + _other_sources():
        for cited in citations(source):
            for _, hits in _resolve(cited):
                for h in hits:
                    rel = h.relative_to(RESULTS).as_posix()
                    (folders if h.is_dir() else files).add("" if rel == "." else rel)
    covering = folders - COLLECTIONS

    def cited(rel: str) -> bool:
        parts = rel.split("/")
        return rel in files or any("/".join(parts[:i]) in covering for i in range(1, len(parts)))

    orphans = [p.relative_to(RESULTS).as_posix() for p in _files()]
    orphans = [rel for rel in orphans if not cited(rel)]
    assert not orphans, "files under docs/results that nothing cites:\n" + "\n".join(orphans)


def test_screen_summaries_read_as_table2_json():
    """scripts/compare_conditions.py pools a summary.json as it pools a table2.json: seeds and, per condition
    and metric, one seed value a seed."""
    summaries = sorted(RESULTS.glob("*/*/summary.json"))
    assert summaries
    for path in summaries:
        summary = json.loads(path.read_text())
        assert summary["summary"]["raw_outputs_at"].startswith("git show "), path
        for name, cond in summary["conditions"].items():
            for metric in ("teacher_score", "unique_regions", "freeze_ratio"):
                if metric in cond:
                    assert len(cond[metric]["seed_values"]) == len(summary["seeds"]), (path, name, metric)
