"""The simulated world: objects and the zoo of hard ones, the scene on the turntable, the VDI/VDE artefacts,
multi-pass motions, and the exact ray casting of a view."""
