"""Perception service package: learned objects localized by the head stereo pairs (adapter over vision/).

``service.py`` is the bus adapter; ``locate.py`` (robot-model glue), ``look_around.py`` (head scan and
turns for the supervisor), ``learn_from_sim.py`` (the model-learning tool) and ``sim_placements.py``
(benchmark/test images) never import zenoh.
"""
