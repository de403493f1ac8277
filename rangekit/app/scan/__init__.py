"""``rangekit scan``: the set-up (simulator or hardware), the turn-over prompt of multi-pass scans, and the
VDI/VDE 2634 artefact scan."""
