"""selpres's partners sweeper: Hydra's basic sweeper, then the sweep's compute-matched partners (``partners=on``).

Hydra instantiates a sweeper only from the ``hydra_plugins`` package; the logic is selpres's
(:mod:`selpres.run.partners`), imported when the sweeper is used, so Hydra's plugin scan at every start stays light.
"""

from hydra._internal.core_plugins.basic_sweeper import BasicSweeper


class PartnerSweeper(BasicSweeper):
    """The sweep's own jobs, then its partners through the same launcher (selpres.run.partners)."""

    def sweep(self, arguments):
        from selpres.run.partners import add_partners

        returns = super().sweep(arguments)
        return add_partners(self, arguments, returns)
