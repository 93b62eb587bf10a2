"""A window that shows frames as they are drawn: gymnasium's ``render_mode="human"``.

pygame is imported only when a window opens, and paced to the environment's real time.
"""

from __future__ import annotations

import numpy as np


class Window:
    """One pygame window sized to the first frame, showing ``fps`` frames per second at most."""

    def __init__(self, title: str, fps: int):
        import pygame

        self._pygame = pygame
        self.title = title
        self.fps = fps
        self._screen = None
        self._clock = pygame.time.Clock()

    def show(self, frame: np.ndarray) -> None:
        pygame = self._pygame
        height, width = frame.shape[:2]
        if self._screen is None:
            pygame.display.init()
            pygame.display.set_caption(self.title)
            self._screen = pygame.display.set_mode((width, height))
        pygame.event.pump()  # keeps the window responsive
        surface = pygame.surfarray.make_surface(np.ascontiguousarray(frame.swapaxes(0, 1)))
        self._screen.blit(surface, (0, 0))
        pygame.display.flip()
        self._clock.tick(self.fps)

    def close(self) -> None:
        if self._screen is not None:
            self._pygame.display.quit()
            self._screen = None
