"""Campaigns: the states and their transition table (``campaign_states``), the set-point
generators (``campaign_plan``), a request checked and planned (``campaign_requests``),
the database and the raw recording (``campaign_repository``), one set-point measured
(``setpoint_collector``, over ``encoder_trace`` for a dynamic one), the service with its
scheduler and runner (``campaigns``) and the raw recording as MCAP (``mcap_files``).
Imports nothing."""
