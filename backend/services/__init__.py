"""Services: what the routes, the lifespan and the command line call, grouped by what each
serves. Each group imports only the groups below it (a ``lint-imports`` contract):

- ``campaigns/``, ``reports/``, ``jobs/`` and ``recordings``: a campaign's commands,
  runner and storage; its reports; the batch jobs (studies, re-processing); recordings
  on demand. None of them imports another.
- ``motion``: the one way to the motion driver (soft limits, ownership, health).
- ``live/``: the acquisition loop and what feeds on it (hub, images, raw frames, the 3-D
  scene, the Foxglove server, the live reference, the kernel warm-up).
- ``calibrations`` and ``store``: bench calibrations; small persistence helpers.
- ``keys``, ``audit``, ``heavy_work``: API keys, the audit trail, the bounded threads
  for long requests.
"""
