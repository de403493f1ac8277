"""The one-shot jobs behind single commands: ``sim render``, ``sim objects``, ``render``, ``register``,
``tof`` / ``stereo``, ``stereo --device`` and ``photometric``."""
