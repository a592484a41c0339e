"""Independent references for the tests and benchmarks: closed forms in NumPy that share
no code with ``designopt``'s kinematics (tests/reference/ur5_closed_form.py: every IK
branch of the UR5 and of a planar 3R, and the best 1/k over each target's solution set)."""
