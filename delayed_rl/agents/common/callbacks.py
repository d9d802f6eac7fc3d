"""Training callbacks with stable-baselines3's protocol, usable without stable-baselines3.

:meth:`~delayed_rl.agents.common.base.TabularAgent.learn` drives any object with SB3's callback methods
(``init_callback``, ``on_training_start``, ``on_rollout_start``, ``update_locals``, ``on_step``,
``on_rollout_end``, ``on_training_end``): SB3's own callbacks (``EvalCallback``,
``CheckpointCallback``, ``StopTrainingOnMaxEpisodes``, ``CallbackList``,
``ProgressBarCallback``, ...) and the small classes here, which need no SB3. A plain callable
``fn(locals_, globals_) -> bool`` (SB3's old-style callback) is wrapped in
:class:`FunctionCallback`, and a list in :class:`CallbackList`.

At every step ``callback.locals`` holds (SB3's names, batched over the one env, then the
unbatched values): ``new_obs``, ``actions``, ``rewards``, ``dones``, ``infos``, ``obs``,
``action``, ``reward``, ``undelayed_reward``, ``terminated``, ``truncated``, ``info``,
``acting_delay_index``, ``total_timesteps`` (the absolute step count at which training ends)
and ``self`` (the agent).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable
from typing import Any

__all__ = [
    "BaseCallback",
    "CallbackList",
    "FunctionCallback",
    "ProgressBarCallback",
    "as_callback",
    "is_callback",
]


class BaseCallback:
    """The callback protocol of SB3's ``BaseCallback``; subclass it and override ``_on_step``.

    Attributes:
        model: the agent being trained (set by ``init_callback``).
        locals: the training loop's variables (see the module docstring).
        n_calls: how many times ``on_step`` was called.
        num_timesteps: the agent's ``num_timesteps`` at the last call.
    """

    def __init__(self, verbose: int = 0):
        self.verbose = verbose
        self.model: Any = None
        self.locals: dict[str, Any] = {}
        self.globals: dict[str, Any] = {}
        self.n_calls = 0
        self.num_timesteps = 0

    def init_callback(self, model: Any) -> None:
        """Remember the agent before training starts."""
        self.model = model
        self._init_callback()

    def _init_callback(self) -> None:
        pass

    def on_training_start(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        """Called once at the start of ``learn()``."""
        self.locals = locals_
        self.globals = globals_
        self.num_timesteps = self.model.num_timesteps
        self._on_training_start()

    def _on_training_start(self) -> None:
        pass

    def on_rollout_start(self) -> None:
        """Called once after ``on_training_start`` (a tabular agent learns at every step)."""

    def update_locals(self, locals_: dict[str, Any]) -> None:
        """Refresh ``self.locals`` with the current step's variables."""
        self.locals.update(locals_)

    def on_step(self) -> bool:
        """Called after every env step; returning ``False`` stops training."""
        self.n_calls += 1
        self.num_timesteps = self.model.num_timesteps
        return self._on_step()

    def _on_step(self) -> bool:
        return True

    def on_rollout_end(self) -> None:
        """Called once before ``on_training_end``."""

    def on_training_end(self) -> None:
        """Called once at the end of ``learn()`` (also when a callback stopped it)."""
        self._on_training_end()

    def _on_training_end(self) -> None:
        pass


class FunctionCallback(BaseCallback):
    """Calls ``fn(locals_, globals_)`` after every step; an explicit ``False`` stops training.

    Unlike SB3's ``ConvertCallback``, a function returning ``None`` lets training continue.

    Args:
        fn: the function.
    """

    def __init__(self, fn: Callable[[dict[str, Any], dict[str, Any]], Any]):
        super().__init__()
        self.fn = fn

    def _on_step(self) -> bool:
        return self.fn(self.locals, self.globals) is not False


class CallbackList(BaseCallback):
    """Runs several callbacks (SB3's or these) in order; any ``False`` stops training.

    Args:
        callbacks: the callbacks.
    """

    def __init__(self, callbacks: Iterable[Any]):
        super().__init__()
        self.callbacks = list(callbacks)

    def init_callback(self, model: Any) -> None:
        """Remember the agent, in every callback."""
        super().init_callback(model)
        for callback in self.callbacks:
            callback.init_callback(model)

    def on_training_start(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        """Start every callback."""
        super().on_training_start(locals_, globals_)
        for callback in self.callbacks:
            callback.on_training_start(locals_, globals_)

    def on_rollout_start(self) -> None:
        """Call every callback's ``on_rollout_start``."""
        for callback in self.callbacks:
            callback.on_rollout_start()

    def update_locals(self, locals_: dict[str, Any]) -> None:
        """Refresh every callback's ``locals``."""
        for callback in self.callbacks:
            callback.update_locals(locals_)

    def on_step(self) -> bool:
        """Step every callback (all of them, even after a ``False``); ``False`` if any said so."""
        super().on_step()
        continue_training = True
        for callback in self.callbacks:
            continue_training = callback.on_step() and continue_training
        return continue_training

    def on_rollout_end(self) -> None:
        """Call every callback's ``on_rollout_end``."""
        for callback in self.callbacks:
            callback.on_rollout_end()

    def on_training_end(self) -> None:
        """End every callback."""
        for callback in self.callbacks:
            callback.on_training_end()


class ProgressBarCallback(BaseCallback):
    """A progress bar over the steps of ``learn()``: tqdm's if installed, else a plain text one.

    Args:
        stream: where the text bar is written (default ``sys.stderr``); tqdm writes to its own.
        use_tqdm: use tqdm when it can be imported (``False`` forces the text bar).
    """

    def __init__(self, stream: Any = None, use_tqdm: bool = True):
        super().__init__()
        self.stream = stream
        self.use_tqdm = use_tqdm
        self._bar: Any = None
        self._total = 0
        self._chunk = 1
        self._pending = 0

    def _on_training_start(self) -> None:
        self._total = max(0, self.locals["total_timesteps"] - self.model.num_timesteps)
        self._chunk = max(1, self._total // 1000)
        self._pending = 0
        tqdm = None
        if self.use_tqdm:
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
        if tqdm is not None:
            self._bar = tqdm(total=self._total, unit="step", file=self.stream)
        else:
            self._bar = _TextBar(self._total, self.stream or sys.stderr)

    def _on_step(self) -> bool:
        self._pending += 1
        if self._pending >= self._chunk:
            self._bar.update(self._pending)
            self._pending = 0
        return True

    def _on_training_end(self) -> None:
        if self._bar is not None:
            if self._pending:
                self._bar.update(self._pending)
                self._pending = 0
            self._bar.close()
            self._bar = None


class _TextBar:
    """``[#####.....] 50% 500/1000 steps 12000 steps/s``, redrawn at most 10 times a second."""

    def __init__(self, total: int, stream: Any, width: int = 30):
        self.total, self.stream, self.width = total, stream, width
        self.n = 0
        self._drawn = -1
        self.start = self._last = time.perf_counter()
        self._draw()

    def update(self, n: int) -> None:
        self.n += n
        now = time.perf_counter()
        if now - self._last >= 0.1 or self.n >= self.total:
            self._last = now
            self._draw()

    def _draw(self) -> None:
        self._drawn = self.n
        fraction = self.n / self.total if self.total else 1.0
        filled = int(round(fraction * self.width))
        rate = self.n / max(time.perf_counter() - self.start, 1e-9)
        self.stream.write(
            f"\r[{'#' * filled}{'.' * (self.width - filled)}] {fraction:4.0%} "
            f"{self.n}/{self.total} steps {rate:,.0f} steps/s"
        )
        self.stream.flush()

    def close(self) -> None:
        if self._drawn != self.n:
            self._draw()
        self.stream.write("\n")
        self.stream.flush()


def is_callback(obj: Any) -> bool:
    """Whether ``obj`` follows the SB3 callback protocol (SB3's callbacks and these)."""
    return callable(getattr(obj, "init_callback", None)) and callable(getattr(obj, "on_step", None))


def as_callback(callback: Any, progress_bar: bool = False) -> Any:
    """Turn ``learn()``'s ``callback`` argument into one callback object, or ``None``.

    Args:
        callback: ``None``, a callback object (SB3's or this module's), a callable
            ``fn(locals_, globals_) -> bool``, or a list of those.
        progress_bar: add a :class:`ProgressBarCallback`.

    Raises:
        TypeError: ``callback`` is none of these.
    """
    if callback is None:
        callbacks = []
    elif isinstance(callback, (list, tuple)):
        callbacks = [_one_callback(item, f"callback[{i}]") for i, item in enumerate(callback)]
    else:
        callbacks = [_one_callback(callback, "callback")]
    if progress_bar:
        callbacks.append(ProgressBarCallback())
    if not callbacks:
        return None
    return callbacks[0] if len(callbacks) == 1 else CallbackList(callbacks)


def _one_callback(obj: Any, name: str) -> Any:
    if is_callback(obj):
        return obj
    if callable(obj):
        return FunctionCallback(obj)
    raise TypeError(
        f"{name} must be None, a callback object (stable-baselines3's BaseCallback or "
        "delayed_rl.agents.common.callbacks.BaseCallback), a callable fn(locals_, globals_) -> bool, "
        f"or a list of those; got {obj!r}"
    )
