"""Interop with the robotics tools labs already use (docs/interop.md).

- ``topics``: the channel names, schemas and units (the contract of an exported file).
- ``foxglove_messages``: our frames, poses and overlays as Foxglove well-known messages
  (``foxglove-sdk``'s typed messages) and as JSON payloads for what no schema carries.
- ``channels``: one set of channels on a ``foxglove.Context``, logged per frame; the MCAP
  export and the live Foxglove server both write through it.
- ``mcap_export`` / ``mcap_import``: HDF5 recording <-> MCAP file.

Encoding is the SDK's (protobuf for the well-known schemas, JSON for ours) and decoding
the ``mcap`` reader's with ``mcap-protobuf-support``: no encoder or decoder of our own.
"""
