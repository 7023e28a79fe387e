"""Task noise of the chapter 6 trials: every condition's episodes replayed under small,
seeded physics perturbations (friction, box masses, pull speed, start-pose jitter), and a
robust search oracle whose plans must hold on the draws it searched with.

An executed episode is a sequence of actions (pull box x, the second arm holding y or none,
for k increments). Replaying those actions in a world that differs from the table's by what
no robot could measure says how much of a rate is the task and how much a knife edge of one
deterministic run."""
