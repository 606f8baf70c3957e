"""Training: the train / evaluate / search commands, tasks and run folders."""
