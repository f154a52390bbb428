"""Train the paper's network from a checkout: ``python train.py schedule=selective topology=6-13-2`` (see README).

A shim: the command is :func:`selpres.run.main.main`, installed as the ``selpres-train`` command.
"""

import sys

try:  # a Ctrl-C before the command's own handling is in place (microseconds of imports): nothing was written
    from selpres.run.main import main
except KeyboardInterrupt:
    print("stopped by SIGINT before the job started: nothing was written", file=sys.stderr)
    sys.exit(130)

if __name__ == "__main__":
    main()
