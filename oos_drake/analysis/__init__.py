"""Worst-case analysis of the attitude loop over the mission (paper section 4).

Modules, in the order of the data flow:

``controller``     the controller JSON of ``oos synth`` (or the labeled baseline)
``models``         closed-loop model arrays (:func:`oos_drake.control.analysis_model.close_loop`):
                   mission (M_330) and docking phases 7 / 8
``subsets``        the uncertainty subsets (total, real, modal, mechanical, additive,
                   multiplicative) and the physical units of the blocks
``workers``        bounds at arbitrary (model, frequency) points in worker processes
``stability``      mu bounds over models x frequencies x subsets (continuation grid),
                   certified peaks per subset (``certified_sweep``)
``tightening``     resolving upper-bound spikes: warm passes, local refinement, searches
``destabilizing``  direct search of destabilizing perturbations (real vertices + complex blocks)
``performance``    worst-case gains ``d -> e_p`` and ``d -> e_u`` per subset
``sensitivity``    which uncertain parameter moves the worst-case mu most
``open_loop``      sampled open-loop gains per uncertainty set (Fig. unc_sensitivity)
``time_check``     linear time-domain simulation of the worst cases against the requirements
``worst_cases``    the ``worst_cases.parquet`` of the mu-guided campaign
``figures``        PNG figures; ``run`` the whole analysis; ``cli`` ``oos analyze``
``confirm``        ``oos confirm``: the worst cases on the nonlinear Drake twin (``oscillation``:
                   decay rate and frequency of its runs); ``margins``: ``oos margins``
``study``          ``oos study``: the margin against one swept scenario value
"""
