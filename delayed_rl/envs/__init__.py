"""The environments of delayed-rl, registered under the ``delayed_rl/`` namespace on import."""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

NAMESPACE = "delayed_rl"
_ENTRY = "delayed_rl.envs.registration:"


def _register(env_id: str, entry: str, **kwargs) -> None:
    """Register ``delayed_rl/<env_id>`` (if not yet registered) with entry point ``entry``."""
    full_id = f"{NAMESPACE}/{env_id}"
    if full_id not in registry:
        register(id=full_id, entry_point=_ENTRY + entry, **kwargs)


def register_envs() -> None:
    """Register every delayed-rl env id (idempotent)."""
    _register("GridWorld-v0", "GridWorld")
    for size in (3, 5, 9):
        _register(f"GridWorld-{size}x{size}-v0", "GridWorld", kwargs={"size": size})
    _register("Roulette-v0", "Roulette")
    _register("EPuckLineFollow-v0", "EPuckLineFollow")
    _register("EPuckLineFollowReal-v0", "EPuckLineFollowReal")


def env_ids() -> list[str]:
    """All registered ``delayed_rl/`` ids, sorted."""
    return sorted(env_id for env_id in registry if env_id.startswith(NAMESPACE + "/"))


register_envs()
