"""Algorithm 1's loop: pre-training, interaction, dynamic demonstrations, early stop (`loop`,
`interaction`), the state a checkpoint keeps (`state`) and the typed rows it logs (`records`)."""
