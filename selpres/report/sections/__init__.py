"""The report's generic sections, one module each; every module has ``section(ctx: Context) -> Section``.

They read any sweep; a study's own section is a module of :mod:`selpres.studies`. The order they appear in lives
in :mod:`selpres.report.build`.
"""
