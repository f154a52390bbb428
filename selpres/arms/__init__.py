"""Arms: the robots whose inverse dynamics are learnt (stage 1 of arm -> data -> presentation -> engine -> loop ->
results -> report).

Owns the paper's two-link planar arm in the closed form of eq. (6) (``two_link``), any serial chain of revolute
joints by eq. (4)-(5) (``serial``: the arm, batched; ``kinematics``: frames, links, rotations; ``dynamics``:
Newton-Euler, composite inertia, LDLᵀ; ``spec``: the YAML spec), and URDF files in and out (``urdf``: chains,
held joints, merged bodies; ``urdf_read``: elements and guards; ``urdf_out``: the writer). An arm maps
(q, q̇, q̈) to τ and (q, q̇, τ) to q̈; nothing here knows about exemplar sets or networks.

May import: ``selpres.errors``, ``selpres.seeding``, ``selpres.storage`` (the foundation), torch and numpy.
"""
