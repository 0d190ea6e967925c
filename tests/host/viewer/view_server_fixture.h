// The in-process viewer the server tests share: a session on a small synthetic pair of awkward
// sizes (no axis a multiple of a workgroup), its server on port 0 and an HTTP client.
#pragma once

#include <memory>
#include <string>

#include "tfmatch/model/synthetic.h"
#include "tfmatch/viewer/view_server.h"
#include "tfmatch/viewer/view_session.h"
#include "vk_test_env.h"
// After Eigen (through the project headers): OpenSSL's headers, which httplib.h includes, define
// macros that break Eigen's product kernels when they come first.
#include <httplib.h>

namespace tfm::test {

// 40 x 32 pictures and TFs of 16 entries: small enough for lavapipe, large enough to see.
inline ViewConfig small_view_config() {
  ViewConfig c;
  c.ref_tf = demo_transfer_function(16);
  c.tf_size = 16;
  c.render.width = 40;
  c.render.height = 32;
  return c;
}

class ViewServerFixture : public GpuTest {
 protected:
  void SetUp() override {
    ref_ = synthetic_reference(13, 11, 9);
    field_ = synthetic_remapped(ref_);
    session_ = std::make_unique<ViewSession>(ctx(), ref_, field_, small_view_config());
    server_ = std::make_unique<ViewServer>(*session_, ViewServerOptions{});
    server_->start();
    client_ = std::make_unique<httplib::Client>("127.0.0.1", server_->port());
    client_->set_read_timeout(120);
  }
  void TearDown() override {
    server_.reset();
    session_.reset();
    GpuTest::TearDown();
  }
  // `path` with the session's token as a query parameter.
  std::string with_token(const std::string& path) const {
    return path + (path.find('?') == std::string::npos ? "?" : "&") + "token=" + server_->token();
  }
  httplib::Result get(const std::string& path) { return client_->Get(with_token(path)); }

  Volume ref_, field_;
  std::unique_ptr<ViewSession> session_;
  std::unique_ptr<ViewServer> server_;
  std::unique_ptr<httplib::Client> client_;
};

}  // namespace tfm::test
