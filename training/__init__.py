"""Training stack (installed as ``alphatank.training``): PPO and SAC learners, the
multi-learner loop over the vector env, opponent schedules, checkpoints usable as
policies, evaluation tables and logging. See docs/training.md. Needs the ``train`` extra."""

from alphatank.extras import require

require("train", "alphatank.training")
