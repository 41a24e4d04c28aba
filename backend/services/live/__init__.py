"""The live path: the acquisition loop (``acquisition``) and what it feeds: the hub
(``hub``), PNG images (``imaging``), raw frames for the browser (``frame_codec``), the
3-D scene (``scene``, ``scene_model``), the Foxglove server (``foxglove_live``); the
reference the live error is measured against (``live_reference``) and the kernels'
warm-up at start (``kernel_warmup``). Imports nothing."""
