"""Features extractors of ACER's policies beyond SB3's own."""

from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, NatureCNN

CNN_SEES = ("newest", "stack")  # what LoopFlagsCNN's CNN sees of the stack


class LoopFlagsCNN(BaseFeaturesExtractor):
    """
    NatureCNN on the newest frame of a stack of ``k`` frames (or on the whole stack), with ``k - 1`` flags appended
    to its features: for each older frame of the stack, 1 where the newest frame equals it (pixel for pixel), else 0.

    A memoryless greedy policy fails in short cycles of poses: pressed against a wall (the frame stays the same,
    flag 1 on) or turning left and right between two poses (the frame equals the one two steps back, flag 2 on),
    while the single frame looks like open floor. The flags tell those states apart at the cost of one CNN pass on
    one frame (a CNN over the whole stack costs more and must learn frame identity from data). Frames from before
    an episode's start are zeros and equal no rendered frame. With ``cnn_sees="stack"`` the CNN sees every frame
    too: the order of the poses, which tells the two ends of a left/right cycle apart, and the flags on top.

    It takes the stack as stored (``uint8``, as ``ACERPolicy.extract_features`` hands it over: ``takes_raw_images``),
    compares frames byte for byte and scales only the newest frame (``x / 255``, as SB3's preprocessing does); a
    float stack (already scaled) is compared to within 1e-4.

    :param observation_space: The stacked observation space, ``k * c`` channels first
    :param frame_stack: ``k``, the frames in the stack (>= 2)
    :param features_dim: Features of the CNN (the flags come on top)
    :param normalized_image: As NatureCNN's
    :param cnn_sees: What the CNN sees: "newest" (the newest frame) or "stack" (every frame, oldest first)
    """

    def __init__(self, observation_space: spaces.Box, frame_stack: int = 2, features_dim: int = 512,
                 normalized_image: bool = False, cnn_sees: str = "newest") -> None:
        if cnn_sees not in CNN_SEES:
            raise ValueError(f"cnn_sees must be one of {CNN_SEES}, got {cnn_sees!r}")
        if frame_stack < 2:
            raise ValueError(f"loop flags compare the newest frame with older ones: frame_stack must be >= 2, got {frame_stack}")
        channels = observation_space.shape[0]
        if channels % frame_stack:
            raise ValueError(f"an observation of {channels} channels is not a stack of {frame_stack} frames")
        super().__init__(observation_space, features_dim + frame_stack - 1)
        self.takes_raw_images = True
        self.k, self.c = frame_stack, channels // frame_stack
        self.seen = channels if cnn_sees == "stack" else self.c  # the CNN's channels, the newest last
        seen = spaces.Box(low=observation_space.low[-self.seen:], high=observation_space.high[-self.seen:],
                          dtype=observation_space.dtype)  # type: ignore[arg-type]
        self.cnn = NatureCNN(seen, features_dim=features_dim, normalized_image=normalized_image)

    def flags(self, observations: th.Tensor) -> th.Tensor:
        """
        :param observations: Stacks, shape (batch, k * c, ...), newest frame last
        :return: Shape (batch, k - 1): column j - 1 is 1.0 where the newest frame equals the one j steps back
        """
        raw = observations.dtype == th.uint8
        frames = observations.reshape(len(observations), self.k, -1)  # (batch, k, pixels), oldest first
        if raw and frames.shape[2] % 8 == 0:  # no scaled copy of the stack, 8 bytes a comparison
            frames = frames.view(th.int64)
        newest, older = frames[:, -1:], frames[:, :-1].flip(1)  # older[:, j - 1]: the frame j steps back
        if raw:
            return (older == newest).all(2).float()
        # Frames are exact renders: equal poses give equal pixels, any move changes some by >= 1/255.
        return ((older - newest).abs().amax(2) < 1e-4).float()

    def forward(self, observations: th.Tensor) -> th.Tensor:
        seen = observations[:, -self.seen:]
        if seen.dtype == th.uint8:
            seen = seen.float() / 255.0
        return th.cat([self.cnn(seen), self.flags(observations)], dim=1)


def loop_flags_kwargs(frame_stack: int, **extractor_kwargs: Any) -> dict[str, Any]:
    """
    The ``policy_kwargs`` that make a policy's features extractor :class:`LoopFlagsCNN` over ``frame_stack`` frames.

    :param frame_stack: The frames of the policy's stack (its ``frame_stack`` policy kwarg too)
    :param extractor_kwargs: LoopFlagsCNN's other settings (``features_dim``, ...)
    """
    return dict(features_extractor_class=LoopFlagsCNN,
                features_extractor_kwargs=dict(extractor_kwargs, frame_stack=frame_stack))
