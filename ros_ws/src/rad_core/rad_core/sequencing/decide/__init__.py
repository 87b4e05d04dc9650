"""Deciding the next action: the action space, episodes, ranking rules and policies, the agents'
text, searches (MCTS, halving, look-ahead, branch and bound) and the sequencer that combines them."""
