//! Measurement planning (`mfd plan`): predicted accuracy and time of a schedule before the first frame, and schedules designed for a frame budget, a time budget or a target accuracy.
