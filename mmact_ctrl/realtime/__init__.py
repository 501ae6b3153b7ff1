"""Real time: the 1 kHz loop paced on the wall clock, the source answering concurrently, deadline statistics."""
