"""`deface serve`: a local web app (Gradio) to drop photos or a clip, watch the fit, turn the textured head in 3D,
relight it and download its output folder. Optional extra ``deface[web]``; only ``app.py`` and ``serve.py`` import
Gradio, so the worker processes (which import ``jobs``) never load it.

config.py    WebConfig: where it writes, how it listens, limits, the operator's fit settings
uploads.py   uploads -> a job's input folder: supported types, count, unique names; the grey-card box
progress.py  time left of a running fit from its stage events, learning each stage's pace as fits finish
jobs.py      the queue: each job is a batch on the worker pool of `deface fit --jobs` (deface.batch)
results.py   a finished fit's files for the page, its skin tone in words, the zip of its folder
relight.py   the loaded fit (deface.load_fit) re-rendered under a preset light turned by the page's sliders
app.py       the page (Gradio Blocks) and its handlers
serve.py     an offline Gradio environment inside the output folder, and the server's life
"""
