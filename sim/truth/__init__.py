"""Accuracy against the simulator's truth: a mesh against the true surface, what a laser scan can see, and
where each view's error comes from."""
