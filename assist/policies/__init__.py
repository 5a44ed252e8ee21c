"""Trained policies shipped with ptw-assist (see ``ppo_roll.json`` for how each was made)."""
