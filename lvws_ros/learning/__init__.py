"""LVWS learning (the only place importing torch): features, the GATN (Eqs. 1-6), the
imitation loss (Eq. 12), expert demonstrations, training, checkpoints, and the learned
policies (LVWS, DBGM, LVWS + rollout)."""
