"""Environments: making a task's env (`make`), the wrappers (time-limit fix, interaction
count), observations and what a network takes of them (`observations`, `network_input`), Atari
(`atari`), and playing a policy for one episode per seed (`episodes`). Nothing here learns."""
