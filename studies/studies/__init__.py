"""Studies of the pipeline cell, above the controller and the simulator: a trial as a group of
processes, campaigns (here or on a Ray cluster), sweeps, re-runs, comparisons, reports and
storyboards. Nothing here runs inside a trial."""
