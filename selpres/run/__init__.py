"""Run: one training job, from a config to its folder (stages 5-6 of arm -> data -> presentation -> engine ->
loop -> results -> report).

Owns the typed config schema (``config``) and the checks a type cannot express, made before any work
(``checks``, with the memory and time estimates of ``estimate``); one writer per job folder (``lock``) and
sweep workers that stop with their sweep (``orphan``); the loop (``train``: prepare -> start (resume) ->
run_epoch ... -> finish); checkpoints and the append-only history (``checkpoint``); TensorBoard
(``tracking``); results.json and a job's identity (``results``) with the seed statistics (``stats``); the
Hydra entry point's guard around ``train()`` (``cli``) and ``selpres-export`` (``export``).

May import: every stage above it (``engines``, ``presentation``, ``data``, ``arms``) and the foundation.
"""
