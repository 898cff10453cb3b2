"""benchmarks/merge_person_sets.py: merged sets read back as one set of all their renders, the folder's other
files linked, and unknown sets refused."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from deface.eval.manifest import read_manifest_rows

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "merge_person_sets.py"
_SPEC = importlib.util.spec_from_file_location("merge_person_sets", _PATH)
merge_person_sets = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(merge_person_sets)


def _folder(root: Path) -> Path:
    folder = root / "truth"
    (folder / "images").mkdir(parents=True)
    lines = ["file\ttone\tset\tyaw"] + [f"{tone}_{name}_{i}.png\t{tone}\t{name}\t0" for tone in ("a", "b")
                                          for name, count in (("three", 3), ("five", 5), ("turn", 3))
                                          for i in range(1, count + 1)]
    (folder / "MANIFEST.tsv").write_text("\n".join(lines) + "\n")
    (folder / "mesh.obj").write_text("v 0 0 0\n")
    return folder


def test_merged_sets_hold_all_their_renders_and_the_others_stay(tmp_path):
    folder, out = _folder(tmp_path), tmp_path / "merged"
    renames = merge_person_sets.renames_of(["eight=five+three"])
    assert merge_person_sets.merge(folder, out, renames) == 16
    _, rows = read_manifest_rows(out, ("file",), "")
    sets = {}
    for row in rows:
        sets.setdefault((row["tone"], row["set"]), []).append(row["file"])
    assert sorted(len(files) for files in sets.values()) == [3, 3, 8, 8]
    assert set(sets) == {("a", "eight"), ("b", "eight"), ("a", "turn"), ("b", "turn")}
    assert (out / "mesh.obj").is_symlink() and (out / "images").resolve() == (folder / "images").resolve()
    assert merge_person_sets.merge(folder, out, renames) == 16  # again over its own links


def test_an_unknown_set_or_a_malformed_merge_is_refused(tmp_path):
    folder = _folder(tmp_path)
    with pytest.raises(SystemExit, match="no set four"):
        merge_person_sets.merge(folder, tmp_path / "merged", {"four": "eight"})
    with pytest.raises(SystemExit, match="is not NEW=SET"):
        merge_person_sets.renames_of(["eight"])
