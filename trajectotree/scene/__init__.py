"""The scene: the hand and object plant built from models/ and the fingers' closed-form kinematics."""
