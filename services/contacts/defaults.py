"""The contact planner's defaults that its service's schema, its CLI and its benchmark share (a light
module: no pinocchio, for the CLI's start-up)."""

from __future__ import annotations

#: The arms' contact forces bounded by what their joints hold (``limb_load.py``, an extension of §2.2;
#: False: friction only, the paper's). On: the plans the simulated arms can hold, the chair egress ends
#: standing (services/contacts/README.md, session 9).
LIMB_LOAD = True
#: f_T's slope k (eq. 1 of the contact paper). 15 with the limb-load bound: a 21-set static walk out of
#: the chair in 261 nodes; 30 (sessions 7-8) needs 1459 nodes with the bound.
SLOPE_K = 15.0
