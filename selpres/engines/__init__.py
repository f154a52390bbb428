"""Engines: the network and the ways it is trained on a presented epoch (stage 4 of arm -> data -> presentation ->
engine -> loop -> results -> report).

Owns the BPN module, topology parsing and the replica weight layout (``model``), its hidden units
(``activations``, one module each), the online-SGD engines (``online``: ``reference``, the executable definition of
correct; ``torch``; ``native``, the C kernel; what they all take, pruned epochs included, checked in ``inputs``),
mini-batch training with today's units and optimizers (``minibatch``: eager torch; ``native_minibatch``: the native
mini-batch kernel), batch-mode training with the speed-up methods of the paper's section 2 (``batch``) and those
methods as ``torch.optim.Optimizer`` classes (``optim``), and the one way to an engine (``factory``: the ``Engine``
protocol, the engines by mode and implementation, ``build_engine``). An engine takes an epoch's order of pattern
indices and updates its replicas; it does not choose the order.

May import: ``selpres.presentation``, ``selpres.data``, ``selpres.arms`` and the foundation (``errors``,
``seeding``, ``storage``, ``native`` for the C kernel).
"""
