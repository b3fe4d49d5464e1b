"""Generators for tests and benchmarks, kept out of the stages: synthetic control libraries and
state models (:mod:`.synthetic`), the procedural gesture stream that exercises the physics
(:mod:`.procedural`) and the offline dynamic-programming synthesis the online controller is
compared with (:mod:`.offline`). Nothing in the product (pipeline, app, commands other than
``bench``) imports this package."""
