"""Train the paper's network from a checkout: ``python train.py schedule=selective topology=6-13-2`` (see README).

A shim: the job is :func:`selpres.run.main.main`, installed as the ``selpres-train`` command.
"""

import sys

try:  # a Ctrl-C while the imports load: one line, exit 130 (nothing is written before Hydra starts)
    from selpres.run.main import main
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    sys.exit(130)

if __name__ == "__main__":
    main()
