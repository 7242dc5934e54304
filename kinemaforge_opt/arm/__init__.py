"""Robot-arm calibration around the joint-space NLP: excitation design (``excitation``), the
nominal Panda (``panda``), MuJoCo "real" arms (``mujoco_real``, ``mjcf``), the classical IDIM-LS
baseline (``idim``) and computed-torque control with ID/FD callables (``control``)."""
