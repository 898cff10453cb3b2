"""The page of `deface serve` (Gradio Blocks) and its handlers.

Why Gradio: it is what the field's demos use (3DDFA_V2, HRN and most face-reconstruction demos), its ``Model3D``
shows the fit's ``mesh.glb`` with its textures in an interactive WebGL viewer, a Hugging Face Space runs a Gradio
``app.py`` as it is, and its handlers are plain Python functions, tested here without a browser. Everything it
needs is in its wheel (no CDN; fonts are local), analytics and share links are off (serve.py).

The handlers return ``{component: value}``; a page holds its job ids in a ``gr.State`` (server side), and a
``gr.Timer`` polls the queue (deface.web.jobs) while the page has unfinished jobs, so a long fit never holds a
request open and a second job shows where it waits.
"""

from __future__ import annotations

import html
import time
from pathlib import Path

import gradio as gr

from deface.fit import presets
from deface.fit.user_options import UsageError
from deface.io.images import InputError
from deface.relight.lights import LightSourceError
from deface.web.config import CARD_REFLECTANCES, WebConfig
from deface.web.jobs import FitService, InputState, WebJob
from deface.web.progress import duration_text
from deface.web.relight import LIGHT_PRESETS, Relighter
from deface.web.results import fit_view
from deface.web.uploads import (
    UploadError,
    box_from_corners,
    box_text,
    draw_box,
    one_person,
    parse_box,
    preview,
    stage_uploads,
)

PRESET_WORDS = {"default": "the full method", "fast": "a quick preview", "paper": "the paper's settings",
                "nextface": "one light: the baseline"}
STAGE_WORDS = {"landmarks": "finding the face", "stage 1": "stage 1: head shape from landmarks",
               "stage 2": "stage 2: lights, shape and light masks", "stage 3": "stage 3: textures",
               "textures": "completing the textures", "writing": "writing the results"}
POLL_SECONDS = 1.0
INTRO = """# deface: a 3D face and its clean texture
Drop a photo of a face (or several, or a short clip), press **Fit**, and watch the fit. You get the textured head in
3D, the skin's own colour with the photo's light and shadows taken out, the lights it found, the head under new
light, and every file as a zip (mesh for Blender, textures, parameters)."""
CARD_HELP = ("If a grey card or white paper is in the photo, click two opposite corners of it here: the fit then "
             "knows how bright the light was, which pins down the skin tone. The box is used for every file of the "
             "job; the default and fast presets use it.")


class WebApp:
    """The page (``blocks``) and its handlers; one per server (``service`` runs every page's jobs)."""

    def __init__(self, config: WebConfig, service: FitService | None = None):
        self.config = config
        self.service = service or FitService(config.output, config.models, config.workers, config.keep_jobs)
        self.relighter = Relighter(config.models)
        self.blocks = self._layout()

    # -- layout ------------------------------------------------------------------------------------------
    def _layout(self) -> gr.Blocks:
        choices = [(f"{name}: {PRESET_WORDS.get(name, presets.DESCRIPTIONS.get(name, ''))}", name)
                   for name in self.config.presets]
        with gr.Blocks(title="deface", analytics_enabled=False) as blocks:
            self.jobs = gr.State([])  # this page's job ids
            self.corner = gr.State(None)  # the grey card's first corner (pixels of the preview)
            self.known = gr.State({})  # what the page shows of its jobs (results listed, the batch zip)
            self.timer = gr.Timer(POLL_SECONDS, active=False)
            gr.Markdown(INTRO)
            with gr.Row():
                with gr.Column(scale=1):
                    self.files = gr.File(label="Photos or a clip", file_count="multiple", type="filepath",
                                         elem_id="uploads")
                    self.one_person = gr.Checkbox(label="These photos are one person: one head and one texture from "
                                                  "all of them", value=False, elem_id="one-person")
                    self.preset = gr.Dropdown(choices, value=self.config.presets[0], label="Preset",
                                              elem_id="preset")
                    with gr.Accordion("Grey card (optional)", open=False):
                        gr.Markdown(CARD_HELP)
                        self.card = gr.Image(label="Click two corners of the card", interactive=False,
                                             elem_id="card", height=320, format="png")
                        with gr.Row():
                            self.card_kind = gr.Radio(list(CARD_REFLECTANCES), value=next(iter(CARD_REFLECTANCES)),
                                                      label="The card is")
                            self.box = gr.Textbox(label="Box: left, top, right, bottom (fractions)",
                                                  placeholder="none", elem_id="card-box")
                        self.clear_card = gr.Button("Clear the box", size="sm")
                    self.fit = gr.Button("Fit", variant="primary", elem_id="fit")
                with gr.Column(scale=1):
                    self.status = gr.Markdown("Nothing fitted yet.", elem_id="status")
            with gr.Column(visible=False, elem_id="results") as self.results:
                with gr.Row():
                    self.result = gr.Dropdown([], label="Result", elem_id="result", scale=2)
                    self.download = gr.DownloadButton("Download this result (zip)", elem_id="download",
                                                      visible=False, scale=1)
                    self.download_all = gr.DownloadButton("Download the whole job (zip)", elem_id="download-all",
                                                          visible=False, scale=1)
                with gr.Row():
                    self.mesh = gr.Model3D(label="The textured head: drag to turn, scroll to zoom", height=420,
                                           clear_color=(0.16, 0.16, 0.18, 1.0), elem_id="viewer", scale=3)
                    with gr.Column(scale=2):
                        self.tone = gr.Markdown(elem_id="tone")
                with gr.Row():
                    self.photo = gr.Image(label="Your photo", interactive=False, height=280, elem_id="photo")
                    self.render = gr.Image(label="The fit in the photo", interactive=False, height=280,
                                           elem_id="render")
                    self.render_face = gr.Image(label="The rendered face", interactive=False, height=280,
                                                elem_id="render-face")
                self.lights = gr.Gallery(label="Lights found: each as a lit sphere, and where it falls (mask)",
                                         columns=6, height=220, format="png", elem_id="lights")
                self.maps = gr.Gallery(label="Texture maps", columns=4, height=300, format="png", elem_id="maps")
                gr.Markdown("### Relight\nThe fitted head under another light, rendered from the loaded fit.")
                with gr.Row():
                    self.light = gr.Dropdown(list(LIGHT_PRESETS), value="studio", label="Light", elem_id="light")
                    self.turn = gr.Slider(-180, 180, value=0, step=5, label="Turn the light (degrees, + to the "
                                                                          "subject's left)", elem_id="turn")
                    self.lift = gr.Slider(-90, 90, value=0, step=5, label="Raise the light (degrees)",
                                          elem_id="lift")
                    self.exposure = gr.Slider(-3, 3, value=0, step=0.25, label="Exposure (EV)", elem_id="exposure")
                with gr.Row():
                    self.relit = gr.Image(label="Relit, in the photo", interactive=False, height=320,
                                          format="png", elem_id="relit")
                    self.relit_face = gr.Image(label="Relit face", interactive=False, height=320, format="png",
                                               elem_id="relit-face")
            self._wire()
        return blocks

    def _wire(self) -> None:
        card = [self.card, self.box, self.corner, self.status]
        quiet = {"show_progress": "hidden"}
        self.files.change(self.preview_card, self.files, card, queue=False, **quiet)
        self.card.select(self.click_card, [self.files, self.corner], card, **quiet)
        self.clear_card.click(self.preview_card, self.files, card, queue=False, **quiet)
        self.fit.click(self.submit, [self.files, self.preset, self.box, self.card_kind, self.jobs, self.one_person],
                       [self.jobs, self.status, self.timer], concurrency_limit=None, show_progress="hidden")
        self.timer.tick(self.refresh, [self.jobs, self.known, self.result],
                        [self.status, self.result, self.known, self.timer, self.results, self.download_all],
                        concurrency_limit=None, show_progress="hidden")
        relight = [self.result, self.light, self.turn, self.lift, self.exposure, self.jobs]
        shown = [self.mesh, self.photo, self.render, self.render_face, self.lights, self.maps, self.tone,
                 self.download, self.relit, self.relit_face]
        self.result.change(self.show, relight, shown, concurrency_id="render")
        for control in (self.light.change, self.turn.release, self.lift.release, self.exposure.release):
            control(self.relight, relight, [self.relit, self.relit_face], concurrency_id="render",
                    show_progress="minimal")

    # -- the grey card -----------------------------------------------------------------------------------
    def preview_card(self, files: list[str] | None) -> dict:
        """The first upload, to draw the card on (the box is cleared)."""
        if not files:
            return {self.card: None, self.box: "", self.corner: None, self.status: gr.skip()}
        try:
            return {self.card: preview(files[0]), self.box: "", self.corner: None, self.status: gr.skip()}
        except InputError as error:
            return {self.card: None, self.box: "", self.corner: None, self.status: _error_line(str(error))}

    def click_card(self, files: list[str] | None, corner, event: gr.SelectData) -> dict:
        """A click on the photo: the first corner, or with the first one the box (a third click starts again)."""
        if not files:
            return {self.card: gr.skip(), self.box: gr.skip(), self.corner: None, self.status: gr.skip()}
        image = preview(files[0])
        point = (float(event.index[0]), float(event.index[1]))
        if corner is None:
            return {self.card: draw_box(image, corner=point), self.box: "", self.corner: point,
                    self.status: gr.skip()}
        box = box_from_corners(corner, point, (image.shape[1], image.shape[0]))
        return {self.card: draw_box(image, box), self.box: box_text(box), self.corner: None, self.status: gr.skip()}

    # -- jobs ----------------------------------------------------------------------------------------------
    def submit(self, files: list[str] | None, preset: str, box: str, card_kind: str, jobs: list[str],
               person: bool = False) -> dict:
        """Queue the uploads as one job (``person``: its photos fitted as one person); every problem is one line in
        the status."""
        try:
            card = parse_box(box)
            config = self.config.fit_config(preset, card, CARD_REFLECTANCES.get(card_kind) if card else None)
            if not files:
                raise UploadError("no file: drop one or more photos, or a clip, first")
            if len(files) > self.config.max_files:
                raise UploadError(f"{len(files)} files: at most {self.config.max_files} per job")
        except (UploadError, UsageError, ValueError) as error:
            return {self.jobs: jobs, self.status: _error_line(str(error)) + "\n\n" + self.status_text(jobs),
                    self.timer: gr.Timer(active=bool(self._unfinished(jobs)))}
        job_id, folder = self.service.new_folder()
        staged = stage_uploads(files, folder, self.config.max_files)
        pairs = one_person(staged) if person else list(zip(staged.files, staged.items, strict=True))
        inputs = [InputState(file, item) for file, item in pairs]
        notes = list(staged.refused)
        if card and not config.tone.scene_light_prior:
            notes.append(f"the grey card is not used: the {preset} preset does not estimate the light level")
        job = self.service.submit(WebJob(job_id, folder, preset, config, inputs, notes))
        jobs = [*jobs, job.id]
        return {self.jobs: jobs, self.status: self.status_text(jobs), self.timer: gr.Timer(active=True)}

    def refresh(self, jobs: list[str], known: dict, selected: str | None) -> dict:
        """The timer's tick: the status of this page's jobs, and the finished results as they come."""
        done = self._results(jobs)
        keys = [key for key, _ in done]
        listed = [list(pair) for pair in done]
        batch_zip = self._latest_batch_zip(jobs)
        update = {self.status: self.status_text(jobs), self.known: {"results": listed, "zip": batch_zip},
                  self.timer: gr.Timer(active=bool(self._unfinished(jobs))), self.result: gr.skip(),
                  self.results: gr.skip(), self.download_all: gr.skip()}
        if listed != known.get("results"):  # a new result, or labels that now name their job
            value = selected if selected in keys else (keys[0] if keys else None)
            update[self.result] = gr.Dropdown(choices=[(label, key) for key, label in done], value=value)
            update[self.results] = gr.Column(visible=bool(keys))
        if batch_zip != known.get("zip"):
            update[self.download_all] = gr.DownloadButton(value=batch_zip, visible=batch_zip is not None)
        return update

    def status_text(self, jobs: list[str]) -> str:
        """Markdown: every job of the page, where it waits or what each of its files is doing."""
        now = time.monotonic()
        parts = []
        with self.service.lock:
            for number, job in enumerate(self._jobs(jobs), 1):
                parts.append(self._job_text(number, job, now))
        return "\n\n".join(parts) if parts else "Nothing fitted yet."

    def _job_text(self, number: int, job: WebJob, now: float) -> str:
        count = len(job.inputs)
        head = f"**Job {number}** ({count} file{'s' if count != 1 else ''}, preset {job.preset})"
        if job.status == "queued":
            ahead = self.service.ahead(job)
            head += f": waiting, {ahead} job{'s' if ahead != 1 else ''} ahead of yours"
        elif job.status == "finished":
            head += f": finished, {job.count('done')} done, {job.count('failed')} failed"
        elif job.status == "removed":
            head += ": its files were removed (this server keeps only the newest jobs)"
        else:
            head += f": {job.count('done')} of {count} done"
        lines = [head]
        if job.error:
            lines.append(_error_line(f"the job could not run: {job.error}"))
        idle = job.workers - job.count("running") if job.status == "running" else 0  # workers still loading
        for state in job.inputs:
            starting = state.status == "queued" and idle > 0
            idle -= starting
            lines.append(f"- {_plain(state.file)}: {self._input_text(state, now, starting)}")
        lines += [f"- {_error_line(line)}" for line in job.refused]
        return "\n".join(lines)

    @staticmethod
    def _input_text(state: InputState, now: float, starting: bool) -> str:
        """One file's line; ``starting``: its job has a worker still loading (the face model, MediaPipe)."""
        if state.status == "done":
            return f"done in {duration_text(state.seconds).removeprefix('about ')}"
        if state.status == "failed":
            return _error_line(state.error or "failed")
        if state.status == "queued":
            if state.retrying:
                return "its worker died; trying once more in a new one"
            return "starting a worker (loading the face model)" if starting else "waiting for a worker"
        clock = state.clock
        if clock is None or clock.stage is None:
            return "reading the file"
        where = STAGE_WORDS.get(clock.stage, clock.stage)
        total = clock.totals.get(clock.stage)
        if total and clock.step:
            where += f", step {clock.step} of {total}"
        return f"{where}; time left: {duration_text(clock.seconds_left(now))}"

    # -- results -------------------------------------------------------------------------------------------
    def show(self, key: str | None, light: str, turn: float, lift: float, exposure: float, jobs: list[str]) -> dict:
        """Every view of one finished fit, and its relit render."""
        outputs = (self.mesh, self.photo, self.render, self.render_face, self.lights, self.maps, self.tone,
                   self.download, self.relit, self.relit_face)
        found = self._finished(key, jobs)
        if found is None:
            return dict.fromkeys(outputs, gr.skip())
        job, state = found
        view = fit_view(job.output(state))
        lights = [item for k, sphere, mask in view.lights
                  for item in ((str(sphere), f"light {k}: lit sphere"), (str(mask), f"light {k}: its mask"))]
        relit = self.relight(key, light, turn, lift, exposure, jobs)
        return {self.mesh: str(view.mesh), self.photo: str(view.photo), self.render: str(view.render),
                self.render_face: str(view.render_face), self.lights: lights,
                self.maps: [(str(path), caption) for caption, path in view.maps], self.tone: view.tone,
                self.download: gr.DownloadButton(value=str(state.zip), visible=state.zip is not None),
                **relit}

    def relight(self, key: str | None, light: str, turn: float, lift: float, exposure: float,
                jobs: list[str]) -> dict:
        """The shown fit under the page's light (a preset turned, raised and exposed)."""
        found = self._finished(key, jobs)
        if found is None:
            return {self.relit: gr.skip(), self.relit_face: gr.skip()}
        job, state = found
        try:
            composite, face = self.relighter.relight(job.output(state), light, float(turn), float(lift),
                                                     float(exposure))
        except (LightSourceError, OSError, ValueError) as error:
            raise gr.Error(f"cannot relight {state.file}: {error}") from None
        return {self.relit: composite, self.relit_face: face}

    # -- lookups -------------------------------------------------------------------------------------------
    def _jobs(self, ids: list[str]) -> list[WebJob]:
        return self.service.jobs(ids)

    def _unfinished(self, ids: list[str]) -> list[WebJob]:
        with self.service.lock:
            return [job for job in self._jobs(ids) if job.status in ("queued", "running")]

    def _results(self, ids: list[str]) -> list[tuple[str, str]]:
        """(key, label) of every finished fit of the page's jobs, in order."""
        with self.service.lock:
            jobs = [job for job in self._jobs(ids) if job.status != "removed"]
            several = len(jobs) > 1
            return [(f"{job.id}/{state.name}", f"{state.file}" + (f" (job {number})" if several else ""))
                    for number, job in enumerate(jobs, 1) for state in job.inputs if state.status == "done"]

    def _latest_batch_zip(self, ids: list[str]) -> str | None:
        with self.service.lock:
            zips = [job.zip for job in self._jobs(ids) if job.zip is not None and job.status == "finished"]
        return str(zips[-1]) if zips else None

    def _finished(self, key: str | None, ids: list[str]) -> tuple[WebJob, InputState] | None:
        """The page's finished fit named by ``key`` (``job id/input name``); None for anything else."""
        if not key or "/" not in key:
            return None
        job_id, name = key.split("/", 1)
        if job_id not in ids:
            return None  # only this page's own jobs (keys come from the browser)
        with self.service.lock:
            for job in self._jobs([job_id]):
                for state in job.inputs:
                    if state.name == name and state.status == "done" and job.status != "removed":
                        return job, state
        return None


def _plain(text: str) -> str:
    """``text`` shown literally in markdown (file names and messages)."""
    return html.escape(text).replace("\\", "\\\\").replace("*", "\\*").replace("_", "\\_").replace("`", "\\`") \
        .replace("[", "\\[").replace("]", "\\]")


def _error_line(message: str) -> str:
    return f'<span class="error-line">✗ {_plain(message)}</span>'


def build(config: WebConfig) -> WebApp:
    """The app for ``config`` (its output folder made and checked)."""
    Path(config.output).mkdir(parents=True, exist_ok=True)
    return WebApp(config)
