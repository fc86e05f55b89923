"""Worst-case analysis of the attitude loop over the mission (paper section 4).

Modules, in the order of the data flow:

``controller``     read the controller JSON of ``oos synth`` (or the labeled baseline)
``loop``           the uncertain closed loop ``d -> e`` with ``Delta_tot = diag(Delta_real,
                   Delta_add, Delta_mul)`` around the scenario LFR
``subsets``        the named uncertainty subsets (total, real, modal, mechanical, additive,
                   multiplicative) and physical units of the blocks
``stability``      mu bounds over configurations x frequencies x subsets, peaks, certificates
``performance``    worst-case gains ``d -> e_p`` and ``d -> e_u`` per subset
``docking``        phase-7 / phase-8 spring-damper studies over the stiffness
``sensitivity``    which uncertain parameter moves worst-case mu most
``time_check``     linear time-domain simulation of the worst cases against the requirements
``worst_cases``    the ``worst_cases.parquet`` of the mu-guided campaign
``figures``        PNG figures; ``run`` the whole analysis; ``cli`` ``oos analyze``
"""
