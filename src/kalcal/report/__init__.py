"""The self-contained HTML report.

- :mod:`kalcal.report.figures`: which figures a run gets, in what order, with their captions.
- :mod:`kalcal.report.html`: the page itself: ``templates/page.html.j2`` filled with the sections, written atomically.
- :mod:`kalcal.report.text`: what the page says about the checks, in plain words.
- :mod:`kalcal.report.markup`: escaping and tables.
- :mod:`kalcal.report.verdicts`: the failures section and the verdicts table.
- :mod:`kalcal.report.run_tables`: scenario and parameters, the last update, timing, reproduce.
- :mod:`kalcal.report.figure_html`: the figures section (embedded PNGs, skipped-figure notes, tables beside them).
"""
