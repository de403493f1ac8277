"""The jobs: each folder is one job, several stages, files and progress, built on the library below it.

    acquire/    a crash-safe session captured view by view, frames written behind the capture
    scan/       ``rangekit scan``: set-up (simulator or hardware), multi-pass prompt, the VDI/VDE artefact scan
    process/    a session into a mesh: views decoded and cached, registered, fused; many sessions on Dask
    report/     ``report.html`` and its panels
    laser/      laser-line calibration, reconstruction, processing and report
    check/      ``rangekit check``: look before scanning
    calibrate   ``rangekit calibrate``: camera, projector, turntable and gamma
    commands/   the one-shot jobs behind single commands (``sim render``, ``render``, ``register``, ...)

Nothing is re-exported here: import a job from its module (``rangekit.app.process.process``), or use the
package's front door (``import rangekit as rk``).
"""
