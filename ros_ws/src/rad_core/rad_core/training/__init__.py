"""Training the learned sequencer: DQN (`dqn`), expert iteration (`expert`), actors on Dask
(`actors`), the allocation dataset and learning curves. Above `sequencing` and `experiment`."""
