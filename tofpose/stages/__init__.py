"""The measurement pipeline's stages (paper §3-§5), one package each: its
orchestration, its compiled kernels (``kernels/``), its plain NumPy/SciPy statement
(``reference/``), its constants and its selection between the two (``arithmetic``)."""
