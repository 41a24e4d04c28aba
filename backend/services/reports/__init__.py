"""Campaign reports: the statistics (``analysis``, ``dynamic_analysis``), what a report
says (``report_content``, ``report_dynamic``), its plots (``report_plots``), the PDF
layout (``report_pdf``) and the four formats (``reports``: CSV, JSON, HTML, PDF).
Imports nothing."""
