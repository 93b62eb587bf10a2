"""CARL 1.1.1's public API on contextrl: change ``from carl.X import Y`` to ``from contextrl.carl.X import Y``.

    from contextrl.carl.envs import CARLCartPole
    from contextrl.carl.context.sampler import ContextSampler
    from contextrl.carl.context.context_space import NormalFloatContextFeature

Every class here is a thin adapter: an environment is contextrl's gymnasium environment
(``contextrl.gymnasium.ContextualGymEnv``) with CARL's constructor, attributes and observation format;
contexts are parsed, validated and selected by contextrl's core. Where CARL is wrong, this face follows
contextrl, and each difference is listed here:

- Every feature acts (CartPole's ``masscart``/``masspole``/``length`` change the dynamics; CARL caches the
  derived masses), and the default context is the original environment (CartPole starts in ±0.05 as
  gymnasium does; CARL's default is ±0.1).
- Values are checked: an unknown feature, a value outside its bounds, NaN, inf or a wrong type is refused
  when the environment or sampler is built (CARL accepts anything and may sample inf/NaN). A declared
  bound may be infinite, as in CARL, but a uniform draw needs finite bounds and is refused otherwise
  (CARL draws inf); a normal's truncation that reaches past the feature's bounds is narrowed to them,
  with a warning (CARL draws values outside the space). ``sigma=0`` draws ``mu``.
- Seeds are honoured: ``reset(seed=...)`` fixes the start states and the random selector's choices, and
  ``ContextSampler(seed=...)`` and ``ContextSpace.sample_contexts(seed=...)`` fix the samples (CARL's random
  selector and ``sample_contexts`` use NumPy's global RNG).
- The observation lies inside ``observation_space``: context values are float32 arrays of shape (1,) in the
  dict form, a float32 vector otherwise (CARL returns Python floats and lists, outside its Box spaces).
  Categorical features appear as their index.
- ``context_id`` (attribute and ``info``) is the key of the ``contexts`` mapping (CARL gives its position,
  which differs when the keys are not 0…n−1); ``context_selector.context_key`` works for the first context
  too (CARL returns None for position 0).
- Setting ``env.context_id`` chooses the context of the next episode (CARL switches the running episode's
  physics mid-way, then its selector moves on at the next reset).
- ``NormalFloatContextFeature`` needs no bounds: without them it is truncated to the feature's bounds.
- ``ContextSpace`` built from a user's own features (``ContextSpace({...})`` or a ``CARLEnv`` subclass's
  ``get_context_features()``) declares a contextrl context type: an infinite bound holds every value a
  float32 (int32) context can store, a default must be finite, categorical choices are strings, and values
  are checked as for a built-in environment. Such a subclass describes contexts only; what runs is a
  registered contextrl environment.
- ``ContextSampler`` takes a list or dict of feature classes, not a ConfigSpace search-space string or
  ``DictConfig``; the feature classes are plain dataclasses, not ConfigSpace hyperparameters. A feature
  is drawn as the kind contextrl declares it (an integer class over a float feature draws floats).
- ``env=`` takes a contextrl environment (``crl.make("CartPole", max_steps=200)``) or None, not a
  gymnasium environment: the dynamics are contextrl's.
- ``contexts`` values are stored at the precision the environment uses (float32).
- ``changes=`` (contextrl's contexts that change within an episode, which CARL lacks) goes to the core's
  step, as in every face; ``context`` then follows the value each step ran under.
"""

from contextrl.carl.envs.registry import register_carl_ids

register_carl_ids()
