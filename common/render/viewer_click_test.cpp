// Clicks in the viewer window (no window needed): the letterbox rect Present draws the composite
// in, window coordinates -> image pixels (unscaled, scaled, letterboxed, a HiDPI framebuffer, the
// bars and the panels), the bounded click queue, the group centre the placement log reports, and
// an offscreen renderer reporting no clicks. The real click through GLFW under Xvfb:
// tests/render/renderer_click_test.cpp.
#include "probeless/render/viewer_click.h"

#include <gtest/gtest.h>

#include <cmath>

#include "probeless/raytrace/mesh.h"
#include "probeless/render/differential.h"
#include "probeless/render/renderer.h"
#include "probeless/testing/expect.h"

namespace probeless::render {
namespace {

void ExpectRect(const PixelRect& r, int x, int y, int w, int h) {
  EXPECT_EQ(r.x, x);
  EXPECT_EQ(r.y, y);
  EXPECT_EQ(r.w, w);
  EXPECT_EQ(r.h, h);
}

WindowClick Click(double x, double y, int ww, int wh, int fw, int fh) {
  WindowClick c;
  c.x = x;
  c.y = y;
  c.window_width = ww;
  c.window_height = wh;
  c.framebuffer_width = fw;
  c.framebuffer_height = fh;
  return c;
}

TEST(ViewerClick, LetterboxRectIsTheLargestCentredRectOfTheImagesAspect) {
  ExpectRect(LetterboxRect(160, 120, 160, 120), 0, 0, 160, 120);
  ExpectRect(LetterboxRect(160, 120, 640, 480), 0, 0, 640, 480);
  ExpectRect(LetterboxRect(160, 120, 800, 480), 80, 0, 640, 480);  // bars left and right
  ExpectRect(LetterboxRect(160, 120, 640, 600), 0, 60, 640, 480);  // bars above and below
  // An odd spare row: GL puts it below the image (viewport y = (600 - 480 - 1) / 2 from the
  // bottom), so the top bar is one row taller.
  ExpectRect(LetterboxRect(160, 120, 640, 601), 0, 61, 640, 480);
  ExpectRect(LetterboxRect(0, 120, 640, 480), 0, 0, 0, 0);
  ExpectRect(LetterboxRect(160, 120, 0, 0), 0, 0, 0, 0);
}

TEST(ViewerClick, WindowCoordinatesBecomeImagePixels) {
  // Unscaled: the window pixel is the image pixel.
  auto p = WindowToImagePixel(Click(37, 21, 160, 120, 160, 120), 160, 120);
  ASSERT_TRUE(p);
  EXPECT_DOUBLE_EQ(p->u, 37);
  EXPECT_DOUBLE_EQ(p->v, 21);
  // The window 4x the image: window pixel 4u + k (k = 0..3) falls in image pixel u.
  for (int k = 0; k < 4; ++k) {
    p = WindowToImagePixel(Click(4 * 100 + k, 4 * 60 + k, 640, 480, 640, 480), 160, 120);
    ASSERT_TRUE(p);
    EXPECT_EQ(std::floor(p->u + 0.5), 100) << k;
    EXPECT_EQ(std::floor(p->v + 0.5), 60) << k;
  }
  p = WindowToImagePixel(Click(402, 242, 640, 480, 640, 480), 160, 120);
  EXPECT_DOUBLE_EQ(p->u, 100.125);
  EXPECT_DOUBLE_EQ(p->v, 60.125);
  // Letterboxed (resized to 800 x 480: 80-pixel bars left and right).
  p = WindowToImagePixel(Click(80 + 402, 242, 800, 480, 800, 480), 160, 120);
  ASSERT_TRUE(p);
  EXPECT_DOUBLE_EQ(p->u, 100.125);
  EXPECT_DOUBLE_EQ(p->v, 60.125);
  EXPECT_FALSE(WindowToImagePixel(Click(79, 242, 800, 480, 800, 480), 160, 120));   // left bar
  EXPECT_FALSE(WindowToImagePixel(Click(720, 242, 800, 480, 800, 480), 160, 120));  // right bar
  // A scaled display: a 400 x 240 window of 800 x 480 framebuffer pixels.
  p = WindowToImagePixel(Click(40 + 201, 121, 400, 240, 800, 480), 160, 120);
  ASSERT_TRUE(p);
  EXPECT_DOUBLE_EQ(p->u, 100.25);
  EXPECT_DOUBLE_EQ(p->v, 60.25);
  // The image's corners stay inside its pixel range.
  p = WindowToImagePixel(Click(0, 0, 640, 480, 640, 480), 160, 120);
  EXPECT_DOUBLE_EQ(p->u, -0.375);
  p = WindowToImagePixel(Click(639, 479, 640, 480, 640, 480), 160, 120);
  EXPECT_LT(p->u, 159.5);
  EXPECT_LT(p->v, 119.5);
  // A panel over the image swallows its clicks; beside it the image gets them.
  const PixelRect panels[] = {{516, 4, 120, 120}};
  EXPECT_FALSE(WindowToImagePixel(Click(600, 50, 640, 480, 640, 480), 160, 120, panels));
  EXPECT_TRUE(WindowToImagePixel(Click(500, 50, 640, 480, 640, 480), 160, 120, panels));
  // Nothing shown yet, or a minimised window.
  EXPECT_FALSE(WindowToImagePixel(Click(10, 10, 640, 480, 640, 480), 0, 0));
  EXPECT_FALSE(WindowToImagePixel(Click(10, 10, 0, 0, 0, 0), 160, 120));
}

TEST(ViewerClick, QueueKeepsTheNewestClicksInOrder) {
  ClickQueue queue;
  EXPECT_TRUE(queue.Take().empty());
  for (int i = 0; i < 3; ++i) queue.Push(Click(i, 0, 1, 1, 1, 1));
  auto clicks = queue.Take();
  ASSERT_EQ(clicks.size(), 3u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(clicks[i].x, i);
  EXPECT_EQ(queue.size(), 0u);
  EXPECT_TRUE(queue.Take().empty());
  for (size_t i = 0; i < ClickQueue::kCapacity + 2; ++i) queue.Push(Click(i, 0, 1, 1, 1, 1));
  EXPECT_EQ(queue.dropped(), 2u);
  clicks = queue.Take();
  ASSERT_EQ(clicks.size(), ClickQueue::kCapacity);
  EXPECT_EQ(clicks.front().x, 2);
  EXPECT_EQ(clicks.back().x, ClickQueue::kCapacity + 1);
}

TEST(ViewerClick, GroupCentreIsTheBoundingBoxCentre) {
  raytrace::Mesh a = raytrace::MakeSphere(0.1f, 16);
  a.TransformBy(raytrace::Transform{raytrace::Mat3::Identity(), {1, 2, 3}});
  raytrace::Mesh b = raytrace::MakeSphere(0.1f, 16);
  b.TransformBy(raytrace::Transform{raytrace::Mat3::Identity(), {1.4f, 2, 3}});
  const raytrace::Mesh* meshes[] = {&a, &b};
  const raytrace::Vec3 c = GroupCentre(meshes);
  EXPECT_NEAR(c.x, 1.2, 1e-5);
  EXPECT_NEAR(c.y, 2, 1e-5);
  EXPECT_NEAR(c.z, 3, 1e-5);
  PROBELESS_EXPECT_THROWS_MESSAGE(GroupCentre({}), RenderError, "render::GroupCentre: no meshes");
  const raytrace::Mesh empty;
  const raytrace::Mesh* none[] = {&empty};
  PROBELESS_EXPECT_THROWS_MESSAGE(GroupCentre(none), RenderError,
                                  "render::GroupCentre: the meshes have no vertices");
}

TEST(ViewerClick, OffscreenRendererReportsNoClicks) {
  RendererOptions options;
  options.width = 32;
  options.height = 24;
  Renderer renderer(options);
  EXPECT_TRUE(renderer.TakeClicks().empty());
}

}  // namespace
}  // namespace probeless::render
