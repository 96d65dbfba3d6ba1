"""The passes of a substep, one module each, each with its own typed group of arrays
(:mod:`clothsim.sim.state`) and left out of a scene's compiled plan when the scene does not use it:

* forces: :mod:`.springs` (the springs' Hooke forces, gathered with gravity), :mod:`.wind`
  (per-triangle aerodynamic drag and lift), :mod:`.pins` (prescribed pin motion);
* constraints and contacts: :mod:`.selfcollide` (the spec's hash or the 27-cell grid),
  :mod:`.colliders` (spheres, planes, capsules, boxes and triangle meshes, fixed or moving),
  :mod:`.provot` (the spec's stretch limit), run in that order by :mod:`.corrections`.

Each pass is written as work items over point ranges (``CHUNKS`` of them), so the thread team's
fast path (:mod:`clothsim.sim.solvers.frame`) and the other integrators' substep
(:mod:`clothsim.sim.solvers.substep`) run the same functions.
"""
