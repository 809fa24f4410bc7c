"""Playing a melody with the learned model (paper Algorithm 1) and the closed loop (Sect. III):
play, notice the failure, adapt, play on.

Contract: :func:`~kbcli.core.playing.play.play` yields one played note at a time (aim, reach,
hear, match); :func:`~kbcli.core.playing.loop.closed_loop` chains playing, a detector and an
adapter as the robot lives it. The world is a callback: the simulator, or a real robot.
"""
