"""Robot-arm calibration around the joint-space NLP: excitation design (``excitation``), the
nominal Panda (``panda``), MuJoCo "real" arms (``mujoco_real``, ``mjcf``), the classical IDIM-LS
baseline (``idim``), computed-torque control with ID/FD callables (``control``) and the
nominal vs IDIM-LS vs kinemaforge_opt comparison of the example and the bench (``side_by_side``)."""
