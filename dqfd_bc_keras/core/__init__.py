"""The learning core: Algorithm 1's mathematics and the models that run it.

`config` (the validated hyperparameters), `losses` (pure loss functions), `expert_terms` and
`methods` (J_E per method, the registry), `networks`, `optimizers`, `replay` (prioritized storage),
`bc` and `uncertainty` (the BC classifier π_bc and its σ²), `agent` (the Q-network's `train_step`)
and `reference` (the same algorithm, eager and slow, to check the fast path against). It imports
the envs and task presets below it, never the demonstrations, training loop, runs or lab above.
"""
