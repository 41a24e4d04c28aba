"""Request and response schemas (pydantic), one module per resource: plain data, no
behaviour. Units in every field name (docs/architecture.md). Building them from
services' types is ``presenters``' job; what several resources share is in
``common``. Imports nothing."""
