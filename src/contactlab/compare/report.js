// The script of report.html, inlined by contactlab.compare.report (no network needed).
// Sets document.body.dataset.status to "ok" once every <img> has loaded and every <video> has
// data, or to "error: <sources>" for those that did not; a video that cannot play is replaced
// by the GIF inside it.
(function () {
  var LIMIT = 5000;
  function imageState(img) {
    return new Promise(function (resolve) {
      function check() { resolve(img.complete && img.naturalWidth > 0 ? null : img.getAttribute('src')); }
      if (img.complete) { check(); return; }
      img.addEventListener('load', check);
      img.addEventListener('error', check);
      setTimeout(check, LIMIT);
    });
  }
  function videoState(video) {
    return new Promise(function (resolve) {
      var done = false;
      function finish(value) { if (!done) { done = true; resolve(value); } }
      function failed() {
        if (done) { return; }
        var fallback = video.querySelector('img');
        var source = video.querySelector('source');
        var src = source ? source.getAttribute('src') : video.getAttribute('src');
        if (!fallback) { finish(src); return; }
        var gif = fallback.cloneNode(true);
        video.replaceWith(gif);
        imageState(gif).then(finish);
      }
      if (video.readyState >= 1) { finish(null); return; }
      if (video.networkState === 3) { failed(); return; }
      video.addEventListener('loadedmetadata', function () { finish(null); });
      video.addEventListener('loadeddata', function () { finish(null); });
      var sources = video.querySelectorAll('source');
      (sources.length ? sources[sources.length - 1] : video).addEventListener('error', failed);
      setTimeout(function () { if (video.readyState >= 1) { finish(null); } else { failed(); } }, LIMIT);
    });
  }
  window.addEventListener('load', function () {
    var videos = Array.prototype.slice.call(document.querySelectorAll('video'));
    Promise.all(videos.map(videoState)).then(function (videoErrors) {
      var images = Array.prototype.slice.call(document.querySelectorAll('img')).filter(function (img) {
        return !img.closest('video');
      });
      return Promise.all(images.map(imageState)).then(function (imageErrors) {
        return videoErrors.concat(imageErrors);
      });
    }).then(function (errors) {
      var bad = errors.filter(Boolean);
      document.body.dataset.status = bad.length ? 'error: ' + bad.join(' ') : 'ok';
    });
  });
})();
