"""The self-contained HTML report.

- :mod:`kalcal.report.figures`: which figures a run gets, in what order, with their captions.
- :mod:`kalcal.report.html`: the page itself (embedded PNGs, inline style, escaped text).
"""
