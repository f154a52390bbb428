"""Run: one training job, from a config to its folder (stages 5-6 of arm -> data -> presentation -> engine ->
loop -> results -> report).

Owns the typed config schema (``config``); the one place the composed config is read and checked (``resolve``: into
the plain specs of ``specs``, a ``JobSpec``, with the checks a type cannot express made before any work: ``checks``,
the optimizer's in ``optimizer``, the memory and time estimates of ``estimate``); one writer per job folder
(``lock``) and sweep workers that stop with their sweep (``orphan``); Ctrl-C, SIGTERM and SIGUSR1 that stop a job
with a checkpoint written (``stop``); what a resolved job determines before the first update (``problem``: prepare,
job_engine); the loop (``train``: resolve -> start (resume) -> run_epoch ... -> finish, reading the JobSpec);
checkpoints and the append-only history (``checkpoint``); TensorBoard (``tracking``); results.json and a job's
identity (``results``; older files read as today's: ``legacy``) with the seed statistics (``stats``), the task's
floor (``floor``) and what ran (``provenance``: versions, commit, platform, native build); the command (``main``:
``selpres-train``, which train.py calls: Hydra's main on the package's configs), a job's life in its folder
(``job``: the lock, skip or refuse, train, and the outcome of ``outcomes``; what a folder holds and how it is put
back: ``folder``), what the command line prints (``cli``) and ``selpres-export`` (``export``).

May import: every stage above it (``engines``, ``presentation``, ``data``, ``arms``) and the foundation.
"""
