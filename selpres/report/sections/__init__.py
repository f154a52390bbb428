"""The report's section blocks, one module each: what a study composes (``verdict``: a reference against every
other method; ``time_to_target``: its tables; ``plots``: error and cost figures, with room for a study's panel and
marks), and the one generic section every report ends with (``runs``, ``section(ctx) -> Section``).

A block takes what a study is about (the reference, the targets, the methods to draw) as arguments; the studies'
sections are the plug-ins' the report is given (:mod:`selpres.report.plugins`). The order of the report lives in
:mod:`selpres.report.build`.
"""
