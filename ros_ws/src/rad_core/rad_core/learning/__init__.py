"""The learned sequencer: graph observations, the attention GNN Q-network, DQN
training, checkpoints, and the Q-policy that plugs into `sequencing.Policy`.

torch is imported only by the modules that need it (network, dqn, policy,
checkpoint); `graph` and `dataset` are numpy-only.
"""
