"""The report's sections, one module each; every module has ``section(ctx: Context) -> Section``.

The order they appear in lives in :data:`selpres.report.build.SECTIONS`.
"""
