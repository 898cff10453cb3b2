"""Re-using a finished fit: new lights (relight), another face's textures (transfer), a rotating view
(turntable). Everything here works on :class:`deface.fit.output.FitOutput` only."""
