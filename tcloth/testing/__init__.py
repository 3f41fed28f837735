"""Reference implementations for checking a simulation, and the stress cases they check,
shared by the tests (tests/) and the benchmarks (tools/). Each reference is independent of
the code it checks: NumPy alone, or a closed form.

- ``crossings``: edge-triangle crossings of a cloth state (against itself and against a
  triangle-mesh obstacle), points inside a closed mesh, closest points on triangles;
- ``colliders``: particles' signed distances to the analytic colliders, paths through a
  thin box or a rigid mesh collider;
- ``meshes``: a geodesic sphere mesh (NumPy alone, so that peers build the same one);
- ``elastica``: the inextensible elastica of Peirce's cantilever (the tip's chord angle
  against alpha = w L^3 / B);
- ``cantilever``: the cantilever strips in tcloth, run to rest;
- ``specimens``: a textile lab's specimens (cantilever strips, Cusick's disc, a bias
  strip) in one scene, with their measurements as ``tcloth.grad`` losses;
- ``contact_cases``: the contact stress set (cloths thrown at each other, falling onto
  colliders, twisted, folded, piled, sliding) and ``run_case``, which checks one at every
  step;
- ``thrown_mesh``: a cloth thrown onto mesh colliders, every integrator;
- ``folding``: the self-contact fold from its saved state;
- ``golden``: the scene snapshots and golden pictures the regression tests compare with;
- ``scripts``: the repository's scene scripts (in a checkout).

Nothing in tcloth imports this package (tests/test_architecture.py): it may use all of
tcloth, and the simulator never depends on its own checks.
"""
