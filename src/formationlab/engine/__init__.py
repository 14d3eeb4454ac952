"""The engine: the one compiled stepping loop (:mod:`.loop`), its contact rule
(:mod:`.contact`) and the host that runs batches of trials on it (:mod:`.trials`).

The stages the loop calls live with their concepts: the law's field in
:mod:`formationlab.controllers.stage`, the robot models in :mod:`formationlab.models.stage`,
obstacles and the safety filter in :mod:`formationlab.safety.stage`. The numpy stepping
driver (:func:`formationlab.integrators.drive`) is the readable specification the loop is
tested against, trial by trial.
"""
