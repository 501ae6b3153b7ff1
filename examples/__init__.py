"""Example chunk sources for ``--source examples.<module>:<factory>`` (README, "Bring your own policy")."""
