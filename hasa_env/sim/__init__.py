"""The simulation core: configuration, roads, vehicle dynamics and sensors, the env set-up,
and the one pure transition shared by the single and the vector env.

- :mod:`~hasa_env.sim.config`: the validated, deep-merged configuration;
- :mod:`~hasa_env.sim.road`: roads as curvature profiles, Frenet geometry, bearings;
- :mod:`~hasa_env.sim.dynamics`: kinematic bicycle, sensors, reward (pure functions,
  scalar and array backends);
- :mod:`~hasa_env.sim.setup`: what a config derives (spaces, episode draws, noise
  blocks, actions, the info layout);
- :mod:`~hasa_env.sim.transition`: :func:`~hasa_env.sim.transition.env_step`.
"""
