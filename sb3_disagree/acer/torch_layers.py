"""Features extractors of ACER's policies beyond SB3's own."""

import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, NatureCNN


class LoopFlagsCNN(BaseFeaturesExtractor):
    """
    NatureCNN on the newest frame of a stack of ``k`` frames, with ``k - 1`` flags appended to its features: for
    each older frame of the stack, 1 where the newest frame equals it (pixel for pixel), else 0.

    A memoryless greedy policy fails in short cycles of poses: pressed against a wall (the frame stays the same,
    flag 1 on) or turning left and right between two poses (the frame equals the one two steps back, flag 2 on),
    while the single frame looks like open floor. The flags tell those states apart at the cost of one CNN pass on
    one frame (a CNN over the whole stack costs more and must learn frame identity from data). Frames from before
    an episode's start are zeros and equal no rendered frame.

    :param observation_space: The stacked observation space, ``k * c`` channels first
    :param frame_stack: ``k``, the frames in the stack (>= 2)
    :param features_dim: Features of the CNN (the flags come on top)
    :param normalized_image: As NatureCNN's
    """

    def __init__(self, observation_space: spaces.Box, frame_stack: int = 2, features_dim: int = 512,
                 normalized_image: bool = False) -> None:
        if frame_stack < 2:
            raise ValueError(f"loop flags compare the newest frame with older ones: frame_stack must be >= 2, got {frame_stack}")
        channels = observation_space.shape[0]
        if channels % frame_stack:
            raise ValueError(f"an observation of {channels} channels is not a stack of {frame_stack} frames")
        super().__init__(observation_space, features_dim + frame_stack - 1)
        self.k, self.c = frame_stack, channels // frame_stack
        newest = spaces.Box(low=observation_space.low[-self.c:], high=observation_space.high[-self.c:],
                            dtype=observation_space.dtype)  # type: ignore[arg-type]
        self.cnn = NatureCNN(newest, features_dim=features_dim, normalized_image=normalized_image)

    def flags(self, observations: th.Tensor) -> th.Tensor:
        """
        :param observations: Stacks, shape (batch, k * c, ...), newest frame last
        :return: Shape (batch, k - 1): column j - 1 is 1.0 where the newest frame equals the one j steps back
        """
        newest = observations[:, -self.c:].flatten(1)
        older = [observations[:, (self.k - 1 - j) * self.c:(self.k - j) * self.c].flatten(1) for j in range(1, self.k)]
        # Frames are exact renders: equal poses give equal pixels, any move changes some by >= 1/255.
        return th.stack([((newest - o).abs().amax(1) < 1e-4).float() for o in older], dim=1)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return th.cat([self.cnn(observations[:, -self.c:]), self.flags(observations)], dim=1)
