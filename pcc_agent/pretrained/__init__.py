"""Pretrained agents shipped with the package, as float16 safetensors files.

See :mod:`pcc_agent.zoo` for the registry and :func:`pcc_agent.zoo.load_pretrained`.
"""
