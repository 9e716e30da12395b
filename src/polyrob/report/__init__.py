"""Figures and the HTML/Markdown report of a run (see :func:`polyrob.report.html.write_report`)."""
