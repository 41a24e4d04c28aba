"""Lab-side models: turntable kinematics, motion profiles, target dynamics, the
relative state and the judgement of a pose against a reference."""
