"""Arms: the robots whose inverse dynamics are learnt (stage 1 of arm -> data -> presentation -> engine -> loop ->
results -> report).

Owns the paper's two-link planar arm in the closed form of eq. (6) (``two_link``), any serial chain of revolute
joints by eq. (4)-(5) (``serial``: the arm, batched; ``kinematics``: frames, links, rotations; ``dynamics``:
Newton-Euler, composite inertia, LDLᵀ; ``spec``: the YAML spec), URDF files in and out (``urdf``: the reader;
``tree``: chains, held joints, merged bodies of any parsed robot tree; ``urdf_read``: elements and guards;
``urdf_out``: the writer), and where a robot node's arm comes from (``sources``: one module per source, a registry;
a user's class by import path). An arm maps (q, q̇, q̈) to τ and (q, q̇, τ) to q̈; nothing here knows about
exemplar sets or networks, nor reads a config: a robot node arrives as plain values (``selpres.run.specs``).

May import: ``selpres.errors``, ``selpres.registry``, ``selpres.seeding``, ``selpres.storage`` (the foundation),
torch and numpy.
"""
