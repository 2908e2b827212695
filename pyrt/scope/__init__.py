"""The software oscilloscope: channels sampled into a ring buffer, triggers, export."""
