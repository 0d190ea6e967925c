// One part of the script of `tfmatch view`'s page; host/viewer/view_page.cpp joins the parts in
// order (viewer_core.js first, viewer_start.js last) inside one strict function scope, so they
// share its names. This one: start-up, last.

// ---- start ------------------------------------------------------------------------------------
async function start() {
  if (!TOKEN) {
    showError('This page needs the address tfmatch view printed, with its ?token=…');
    return;
  }
  setupViewInteraction();
  setupSlices();
  setupSolverForm();
  initSeries();
  $('#histogram-scale').addEventListener('change', loadPlots);
  try {
    await loadState();
  } catch (e) {
    showError('could not load the state: ' + e.message);
    return;
  }
  const st = V.state;
  followServer();
  defaultSize = initialSize(st);
  buildSizeChoices();
  resetCamera();
  updateCameraUI();
  const d = st.grid.dims;
  if (st.mode === 'ensemble' && st.ensemble && st.ensemble.point) setSliceAxis('z', st.ensemble.point[2]);
  else setSliceAxis('z', Math.floor(d[2] / 2));
  if (st.job && st.job.state === 'running') {
    startJob(st.job.id, st.job.kind);
    return;
  }
  clearError();
  await Promise.all([loadImages(true), loadSlices(), loadPlots()]);
}

start();
