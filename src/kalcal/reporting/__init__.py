"""The self-contained HTML report.

- :mod:`kalcal.reporting.figures`: which figures a run gets, in what order, with their captions.
- :mod:`kalcal.reporting.html`: the page itself: ``templates/page.html.j2`` filled with the sections (the figures section among them), written atomically.
- :mod:`kalcal.reporting.text`: what the page says about the checks, in plain words.
- :mod:`kalcal.reporting.markup`: escaping and tables.
- :mod:`kalcal.reporting.verdicts`: the failures section and the verdicts table.
- :mod:`kalcal.reporting.run_tables`: scenario and parameters, the last update, timing, reproduce.
"""
