"""Image-based control environments of the PCC paper, registered in Gymnasium.

Importing this package registers the ids of :data:`pcc_envs.registry.ENV_TABLE`
(``pcc/Planar-v0``, ``pcc/PendulumSwingUp-v0``, ...). It never imports torch.

>>> import gymnasium as gym
>>> import pcc_envs  # noqa: F401
>>> env = gym.make("pcc/Planar-v0")
>>> obs, info = env.reset(seed=0)
>>> obs.shape, obs.dtype
((1, 40, 40), dtype('uint8'))
"""

from pcc_envs.registry import ENV_TABLE, register_all

ENV_IDS: tuple[str, ...] = tuple(row.env_id for row in ENV_TABLE)

register_all()

__all__ = ["ENV_IDS", "ENV_TABLE", "register_all"]
