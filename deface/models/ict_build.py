"""Build the ICT-FaceKit face-area pack from the upstream repository's OBJ files, and fetch that repository.

Upstream (https://github.com/ICT-VGL/ICT-FaceKit, MIT) ships ``FaceXModel/generic_neutral_mesh.obj``,
``identity000.obj`` ... ``identity099.obj`` and 53 expression OBJs, all with the same 26,719 vertices in the
same order. The face area is vertices 0..9408 and faces 0..9229 (upstream README). The pack keeps the face
area's positions and faces, all UVs, and the morph targets as float16 deltas from the neutral mesh.
"""

from __future__ import annotations

import hashlib
import io
import json
import shutil
import tempfile
import urllib.error
import urllib.request
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

FACE_VERTICES = 9409
FACE_FACES = 9230
NUM_IDENTITIES = 100
NEUTRAL_OBJ = "generic_neutral_mesh.obj"
UPSTREAM_ZIP_URL = "https://github.com/ICT-VGL/ICT-FaceKit/archive/refs/heads/master.zip"
UNITS_NOTE = "cm (ICT obj units); identity weights ~ N(0,1) per ICT sample_random.py"

# Multi-PIE 68 landmark vertex ids, copied from the upstream README ("Facial Landmarks", 0-indexed).
LANDMARKS_MULTIPIE68 = (
    1225,
    1888,
    1052,
    367,
    1719,
    1722,
    2199,
    1447,
    966,
    3661,
    4390,
    3927,
    3924,
    2608,
    3272,
    4088,
    3443,
    268,
    493,
    1914,
    2044,
    1401,
    3615,
    4240,
    4114,
    2734,
    2509,
    978,
    4527,
    4942,
    4857,
    1140,
    2075,
    1147,
    4269,
    3360,
    1507,
    1542,
    1537,
    1528,
    1518,
    1511,
    3742,
    3751,
    3756,
    3721,
    3725,
    3732,
    5708,
    5695,
    2081,
    0,
    4275,
    6200,
    6213,
    6346,
    6461,
    5518,
    5957,
    5841,
    5702,
    5711,
    5533,
    6216,
    6207,
    6470,
    5517,
    5966,
)

# The 53 ARKit-style expressions of ICT-FaceKit (upstream vertex_indices.json "expressions"), pack order.
EXPRESSION_NAMES = (
    "browDown_L",
    "browDown_R",
    "browInnerUp_L",
    "browInnerUp_R",
    "browOuterUp_L",
    "browOuterUp_R",
    "cheekPuff_L",
    "cheekPuff_R",
    "cheekSquint_L",
    "cheekSquint_R",
    "eyeBlink_L",
    "eyeBlink_R",
    "eyeLookDown_L",
    "eyeLookDown_R",
    "eyeLookIn_L",
    "eyeLookIn_R",
    "eyeLookOut_L",
    "eyeLookOut_R",
    "eyeLookUp_L",
    "eyeLookUp_R",
    "eyeSquint_L",
    "eyeSquint_R",
    "eyeWide_L",
    "eyeWide_R",
    "jawForward",
    "jawLeft",
    "jawOpen",
    "jawRight",
    "mouthClose",
    "mouthDimple_L",
    "mouthDimple_R",
    "mouthFrown_L",
    "mouthFrown_R",
    "mouthFunnel",
    "mouthLeft",
    "mouthLowerDown_L",
    "mouthLowerDown_R",
    "mouthPress_L",
    "mouthPress_R",
    "mouthPucker",
    "mouthRight",
    "mouthRollLower",
    "mouthRollUpper",
    "mouthShrugLower",
    "mouthShrugUpper",
    "mouthSmile_L",
    "mouthSmile_R",
    "mouthStretch_L",
    "mouthStretch_R",
    "mouthUpperUp_L",
    "mouthUpperUp_R",
    "noseSneer_L",
    "noseSneer_R",
)


class BuildError(RuntimeError):
    """The upstream files are missing or malformed (one-line message)."""


class FetchError(RuntimeError):
    """Downloading the upstream repository failed (one-line, actionable message)."""


def read_obj(path: Path, with_faces: bool = True) -> dict[str, np.ndarray]:
    """Positions [V, 3], UVs [U, 2] and faces [F, 4] (v and vt ids, -1 pads triangles) of an OBJ file."""
    positions, uvs, face_v, face_uv = [], [], [], []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for line in handle:
            if line.startswith("v "):
                positions.append(line[2:])
            elif line.startswith("vt "):
                uvs.append(line[3:])
            elif with_faces and line.startswith("f "):
                corners = line.split()[1:]
                if len(corners) not in (3, 4):
                    raise BuildError(
                        f"{path}: only triangles and quads are supported, got {len(corners)} corners"
                    )
                ids = [c.split("/") for c in corners] + [["0", "0"]] * (4 - len(corners))  # pads to -1
                face_v.append([int(i[0]) - 1 for i in ids])
                face_uv.append([int(i[1]) - 1 if len(i) > 1 and i[1] else -1 for i in ids])
    out = {"positions": np.array(" ".join(positions).split(), np.float64).reshape(-1, 3)}
    if uvs:
        out["uv"] = np.array(" ".join(uvs).split(), np.float64).reshape(
            -1, 3 if len(uvs[0].split()) == 3 else 2
        )[:, :2]
    if with_faces:
        out["faces_v"] = np.array(face_v, np.int64).reshape(-1, 4)
        out["faces_uv"] = np.array(face_uv, np.int64).reshape(-1, 4)
    return out


def find_obj_dir(source: Path) -> Path:
    """The folder holding the upstream OBJs: ``source`` itself or ``source/FaceXModel``."""
    for candidate in (source, source / "FaceXModel"):
        if (candidate / NEUTRAL_OBJ).is_file():
            return candidate
    raise BuildError(
        f"no {NEUTRAL_OBJ} in {source} or {source / 'FaceXModel'}; point --from at an ICT-FaceKit checkout"
    )


def build_ict_pack(
    source: str | Path, require_complete: bool = True, progress: Callable[[str], None] | None = None
) -> dict[str, np.ndarray]:
    """Arrays of the face-area pack built from the upstream OBJs in ``source`` (see the module docstring).

    With ``require_complete=False`` only the identities and expressions present are packed (in upstream
    order); this is how the builder is tested on a subset.
    """
    obj_dir = find_obj_dir(Path(source))
    neutral_obj = read_obj(obj_dir / NEUTRAL_OBJ)
    neutral = neutral_obj["positions"]
    if len(neutral) < FACE_VERTICES or len(neutral_obj["faces_v"]) < FACE_FACES:
        raise BuildError(
            f"{obj_dir / NEUTRAL_OBJ}: fewer vertices/faces than the ICT face area; not ICT-FaceKit?"
        )
    faces_v = neutral_obj["faces_v"][:FACE_FACES]
    faces_uv = neutral_obj["faces_uv"][:FACE_FACES]
    if faces_v.max() >= FACE_VERTICES:
        raise BuildError(
            "the first 9,230 faces use vertices beyond the face area; not the ICT-FaceKit topology"
        )
    identity_names = [f"identity{i:03d}" for i in range(NUM_IDENTITIES)]
    expression_names = _expression_names(obj_dir)
    arrays = {
        "neutral": neutral[:FACE_VERTICES].astype(np.float32),
        "uv": neutral_obj["uv"].astype(np.float32),
        "faces_v": faces_v.astype(np.int32),
        "faces_uv": faces_uv.astype(np.int32),
    }
    for kind, names in (("identity", identity_names), ("expression", expression_names)):
        present = [n for n in names if (obj_dir / f"{n}.obj").is_file()]
        missing = sorted(set(names) - set(present))
        if missing and require_complete:
            raise BuildError(f"{len(missing)} {kind} OBJs missing in {obj_dir} (e.g. {missing[0]}.obj)")
        deltas = np.zeros((len(present), FACE_VERTICES, 3), np.float16)
        for i, name in enumerate(present):
            if progress:
                progress(name)
            target = read_obj(obj_dir / f"{name}.obj", with_faces=False)["positions"]
            if target.shape != neutral.shape:
                raise BuildError(f"{name}.obj has {len(target)} vertices, the neutral mesh {len(neutral)}")
            deltas[i] = (target[:FACE_VERTICES] - neutral[:FACE_VERTICES]).astype(np.float16)
        arrays[f"{kind}_deltas"] = deltas
        arrays[f"{kind}_names"] = np.array(present)
    arrays["units"] = np.array(UNITS_NOTE)
    arrays["landmarks_multipie68"] = np.array(LANDMARKS_MULTIPIE68, np.int32)
    return arrays


def _expression_names(obj_dir: Path) -> list[str]:
    """Upstream's list (vertex_indices.json beside the OBJs, if present), else the 53 known names."""
    index = obj_dir / "vertex_indices.json"
    if index.is_file():
        try:
            return list(json.loads(index.read_text())["expressions"])
        except (KeyError, ValueError) as error:
            raise BuildError(f"{index}: cannot read the 'expressions' list ({error})") from error
    return list(EXPRESSION_NAMES)


def save_pack(arrays: dict[str, np.ndarray], path: str | Path) -> Path:
    """Write the pack as a deterministic npz (fixed zip timestamps, sorted keys): same arrays, same bytes."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for key in sorted(arrays):
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, np.asanyarray(arrays[key]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, buffer.getvalue())
    tmp.replace(path)
    return path


def content_sha256(path: str | Path) -> str:
    """SHA-256 over an npz's arrays (sorted key, dtype, shape, bytes): independent of zip packaging."""
    digest = hashlib.sha256()
    with np.load(path, allow_pickle=False) as pack:
        for key in sorted(pack.files):
            array = np.ascontiguousarray(pack[key])
            digest.update(f"{key}|{array.dtype.str}|{array.shape}|".encode())
            digest.update(array.tobytes())
    return digest.hexdigest()


def fetch_upstream(
    destination: str | Path,
    url: str = UPSTREAM_ZIP_URL,
    timeout: float = 10.0,
    progress: Callable[[int], None] | None = None,
) -> Path:
    """Download and unpack the upstream repository zip into ``destination``; returns the OBJ folder.

    Raises :class:`FetchError` with what to do offline when the URL cannot be reached within ``timeout``.
    """
    destination = Path(destination)
    offline_help = (
        f"cannot download {url}: {{reason}}. Offline: on a machine with internet download "
        f"{UPSTREAM_ZIP_URL}, unzip it, copy it here and run "
        "`deface models build ict --from <unzipped folder>`"
    )
    try:
        response = urllib.request.urlopen(url, timeout=timeout)  # noqa: S310 (a fixed https URL by default)
    except (TimeoutError, urllib.error.URLError, OSError) as error:
        reason = getattr(error, "reason", error)
        raise FetchError(offline_help.format(reason=reason)) from error
    destination.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=destination) as tmp:
        archive = Path(tmp) / "ict-facekit.zip"
        try:
            with response, open(archive, "wb") as out:
                done = 0
                while chunk := response.read(1 << 20):
                    out.write(chunk)
                    done += len(chunk)
                    if progress:
                        progress(done)
        except (TimeoutError, OSError) as error:
            raise FetchError(offline_help.format(reason=f"download interrupted ({error})")) from error
        try:
            with zipfile.ZipFile(archive) as zipped:
                members = [
                    m for m in zipped.namelist() if "/FaceXModel/" in m and m.endswith((".obj", ".json"))
                ]
                if not members:
                    raise FetchError(f"{url} holds no FaceXModel/*.obj; is it the ICT-FaceKit repository?")
                target = destination / "FaceXModel"
                target.mkdir(exist_ok=True)
                for member in members:
                    with zipped.open(member) as src, open(target / Path(member).name, "wb") as dst:
                        shutil.copyfileobj(src, dst)
        except zipfile.BadZipFile as error:
            raise FetchError(f"{url} did not return a zip archive ({error})") from error
    return destination / "FaceXModel"
