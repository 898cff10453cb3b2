"""`deface models ...` through typer's CliRunner; the registry."""

from __future__ import annotations

import typer
from typer.testing import CliRunner

from deface.cli.models import register
from deface.models import registry

runner = CliRunner()


def _app() -> typer.Typer:
    app = typer.Typer()
    register(app)

    @app.callback()
    def main() -> None:  # a root callback keeps "models" a sub-command
        pass

    return app


def _isolate(monkeypatch, tmp_path):
    monkeypatch.setenv("DEFACE_MODELS", str(tmp_path / "env"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


def test_registry_entries_are_complete():
    keys = [e.key for e in registry.MODEL_FILES]
    assert len(keys) == len(set(keys))
    paths = {e.relative_path for e in registry.MODEL_FILES}
    assert {
        "bfm2017/model2017-1_face12_nomouth.h5",
        "albedomm/albedoModel2020_face12_albedoPart.h5",
        "facenet/20180402-114759-vggface2.pt",
        "face-parsing/79999_iter.pth",
        "ict-facekit/ict_face_area_v9409_f16.npz",
    } <= paths
    assert registry.model_file("ict").required and registry.model_file("ict").sha256
    assert [e.key for e in registry.select(["bfm"])] == ["bfm2017", "albedomm"]


def test_list_works(monkeypatch, tmp_path):
    _isolate(monkeypatch, tmp_path)
    result = runner.invoke(_app(), ["models", "list"])
    assert result.exit_code == 0, result.output
    assert "bfm2017" in result.output and "missing" in result.output


def test_check_missing_required_fails_with_one_line(monkeypatch, tmp_path):
    _isolate(monkeypatch, tmp_path)
    result = runner.invoke(_app(), ["models", "check", "--models", str(tmp_path / "empty")])
    assert result.exit_code == 1
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1
    assert "ict-facekit/ict_face_area_v9409_f16.npz" in errors[0] and "deface models fetch ict" in errors[0]


def test_check_named_optional_group(monkeypatch, tmp_path, shared):
    _isolate(monkeypatch, tmp_path)
    result = runner.invoke(_app(), ["models", "check", "bfm", "--models", str(shared / "models")])
    assert result.exit_code == 1
    assert "faces.dmi.unibas.ch" in result.output and "AlbedoMM" in result.output


def test_check_passes_with_pack_and_verifies_checksum(monkeypatch, tmp_path, shared):
    _isolate(monkeypatch, tmp_path)
    status = registry.status(registry.model_file("ict"), shared / "models", verify=True)
    assert status.checksum == "ok"
    result = runner.invoke(_app(), ["models", "check", "--models", str(shared / "models")])
    assert result.exit_code == 0, result.output


def test_check_detects_corrupt_file(monkeypatch, tmp_path):
    _isolate(monkeypatch, tmp_path)
    bad = tmp_path / "m" / "ict-facekit" / "ict_face_area_v9409_f16.npz"
    bad.parent.mkdir(parents=True)
    bad.write_bytes(b"not a pack")
    result = runner.invoke(_app(), ["models", "check", "ict", "--models", str(tmp_path / "m")])
    assert result.exit_code == 1 and "checksum mismatch" in result.output


def test_fetch_offline_message(monkeypatch, tmp_path):
    _isolate(monkeypatch, tmp_path)
    result = runner.invoke(
        _app(),
        [
            "models",
            "fetch",
            "ict",
            "--url",
            "http://127.0.0.1:9/",
            "--timeout",
            "2",
            "--models",
            str(tmp_path / "m"),
        ],
    )
    assert result.exit_code == 1
    assert "cannot download http://127.0.0.1:9/" in result.output
    assert "deface models build ict --from" in result.output
    assert not (tmp_path / "m" / "ict-facekit" / "ict_face_area_v9409_f16.npz").exists()


def test_build_from_sample_needs_complete_set(monkeypatch, tmp_path, shared):
    _isolate(monkeypatch, tmp_path)
    raw = shared / "models" / "ict-facekit" / "raw-sample"
    result = runner.invoke(
        _app(), ["models", "build", "ict", "--from", str(raw), "--models", str(tmp_path / "m")]
    )
    assert result.exit_code == 1 and "identity OBJs missing" in result.output
