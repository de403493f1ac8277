"""The headless renderer: meshes and clouds ray cast into RGB pictures with no display and no GPU (reports,
``rangekit render``, benchmarks)."""
