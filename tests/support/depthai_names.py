"""Which dotted depthai names (``"node.Camera"``, ``"CameraControl.AutoFocusMode.OFF"``) a module lacks."""


def missing_names(module, paths) -> list[str]:
    """The entries of ``paths`` that ``module`` does not have, attribute by attribute."""
    missing = []
    for path in paths:
        obj = module
        for part in path.split("."):
            if not hasattr(obj, part):
                missing.append(path)
                break
            obj = getattr(obj, part)
    return missing
